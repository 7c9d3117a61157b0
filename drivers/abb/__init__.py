"""ABB controller driver: line protocol, client, simulated controller, and the RAPID server."""
