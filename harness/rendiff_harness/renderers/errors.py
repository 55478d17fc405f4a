"""Exceptions shared by the backends, the registry and the CLI.

They exist so that *expected* failures (a renderer missing, a renderer crashing,
a scene it cannot model) reach the user as one clear line naming the backend,
while anything else stays a real traceback that points at a bug in rendiff.
"""

from __future__ import annotations


class BackendError(Exception):
    """A backend ran but failed (non-zero exit, timeout, unreadable output).

    The message must name what failed and, where possible, carry the renderer's
    own last words (e.g. the tail of its stderr).
    """


class BackendUnavailable(BackendError):
    """The backend cannot run on this machine (binary or package missing).

    The message must say what to install, so that the report is actionable.
    """


class BackendSkipped(BackendError):
    """The renderer itself declined the scene (a command renderer's exit status 3).

    The message is the reason, e.g. "no Vulkan adapter"; `render` reports it as *skipped*
    (exit 3, the skip line on stdout), never as an error.
    """
