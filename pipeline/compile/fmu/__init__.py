"""FMU export (FMI 2.0 Model Exchange) of compiled models."""
