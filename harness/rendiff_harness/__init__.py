"""rendiff's Python side: external renderer backends and the OpenImageIO comparison.

The Rust core resolves scenes and orchestrates runs; this package renders the
resolved scene with renderers that only have Python or CLI front ends, and
compares buffers with OpenImageIO + numpy.
"""
