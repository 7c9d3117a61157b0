"""The application: file formats, the command line, benchmarks."""
