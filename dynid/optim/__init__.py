"""dynid.optim."""
