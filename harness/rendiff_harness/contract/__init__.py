"""What rendiff and every renderer agree on, and nothing else: the camera and its projection,
the resolved scene, the buffer EXR, the run's manifest, results.json, the shared vocabulary and
the closed-form local shading. Nothing here imports from the rest of the harness
(tests/test_layout.py checks it), so the judge and the renderers can both stand on it."""
