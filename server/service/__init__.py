"""The workstation service's machinery: the app, jobs and their worker processes, events, leases, security, settings, the page and viewer it serves."""
