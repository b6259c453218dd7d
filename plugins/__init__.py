"""Built-in plugins of mcl; each registers through the same hooks as third-party plugins."""
