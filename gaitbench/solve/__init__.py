"""Solving steps and chaining them into walks: the solver interface, NLP evaluation, the step-by-step walk with its
retry ladder and back-up, the multi-step chain, the One Phase strategy and Decrease & Conquer's trajectory synthesis
that other strategies build on, and the verification of every step by re-simulation."""
