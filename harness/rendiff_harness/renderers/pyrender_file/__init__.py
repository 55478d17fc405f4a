"""pyrender rendering the user's original glTF files through trimesh (backend.py)."""
