"""Mitsuba 3 rendering the user's original OBJ files (`mitsuba_file`)."""
