"""One module per external renderer; see registry.py for the list."""
