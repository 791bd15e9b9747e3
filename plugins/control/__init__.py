"""Built-in tracking plugins: controllers, observers and disturbances."""
