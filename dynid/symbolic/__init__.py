"""dynid.symbolic."""
