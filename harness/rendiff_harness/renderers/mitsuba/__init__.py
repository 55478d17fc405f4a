"""Mitsuba 3 (backend.py: exporter, reader, precision and `SPEC`)."""
