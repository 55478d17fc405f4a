"""Everything that renders: one `BackendSpec` per backend (spec.py), the registry as the only list
of them (registry.py), one folder per built-in backend (povray/, pyrender/, mitsuba/, each a
backend.py whose `SPEC` is its whole declaration), the core's specs (core.py), renderers declared
by a command (command.py, declared.py), and the processes that run them (worker.py, children.py).

Imports: the contract, and from the judge only its tolerance types (judge/tolerance.py,
judge/camera_budget.py), which a spec's precision models are made of (tests/test_layout.py)."""
