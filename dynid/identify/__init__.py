"""dynid.identify."""
