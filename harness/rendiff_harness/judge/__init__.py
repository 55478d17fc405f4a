"""Everything that decides a verdict: the buffer table and the comparison of each buffer (ids,
depth, normals, rgb), the verifier's classes, the tolerance and calibration machinery, the
metamorphic relations and the expectations.

Imports: the contract, and from the renderers only the spec types (renderers/spec.py); a
backend's spec reaches the judge through the lookup its caller passes in
(`renderers.spec.SpecLookup`), never through the registry (tests/test_layout.py)."""
