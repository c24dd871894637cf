"""The physical systems of the paper, each a function returning ``(problem, initial_state)``."""

__all__: list[str] = []
