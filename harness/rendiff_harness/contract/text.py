"""User text in messages: one home for showing it safely (Rust's `scene::printable`).

A path, a name or a renderer's output can hold a newline (a message that forges a second
line), a terminal escape or a bidi override; shown escaped, it stays one line that reads as
what it is."""

from __future__ import annotations

_ESCAPES = {"\t": "\\t", "\n": "\\n", "\r": "\\r", "\0": "\\0"}


def printable(text: str, max_chars: int = 2000) -> str:
    """Control, format (bidi) and other unprintable characters escaped, clipped to `max_chars`."""
    out = []
    for i, c in enumerate(text):
        if i >= max_chars:
            out.append(f"... ({len(text) - i} more characters)")
            break
        out.append(c if c.isprintable() else _ESCAPES.get(c, f"\\u{{{ord(c):x}}}"))
    return "".join(out)
