"""pyrender on OSMesa (backend.py: exporter, reader, precision and `SPEC`; shaders/: its GLSL)."""
