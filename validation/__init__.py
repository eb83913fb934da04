"""validation: the spring model against a linear-elastic finite-element reference (scikit-fem)."""

__all__ = []
