"""Built-in reporters: CSV tables and the HTML report."""
