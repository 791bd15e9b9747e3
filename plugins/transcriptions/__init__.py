"""Built-in transcription plugins: Hermite-Simpson and trapezoidal collocation, discrete mechanics (DMOC)."""
