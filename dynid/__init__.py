"""dynid: identify the dynamic model of a robot arm, then explain what the model still gets wrong."""

from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["__version__"]
