"""Built-in objective plugins: net power (the thesis), actuator work, squared torques."""
