"""POV-Ray 3.7 (backend.py: exporter, reader, precision and `SPEC`)."""
