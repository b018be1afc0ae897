"""Templates and the standalone loader shipped with every C export."""

__all__: list[str] = []
