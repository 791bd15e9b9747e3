"""Built-in strategy plugins: One Phase, warm start, Decrease & Conquer, whole walk."""
