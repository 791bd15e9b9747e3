"""One step as an optimal control problem and its NLP: the gait problem, the transcription base class, the NLP
with exact sparse derivatives, compiled functions, scaling and the objective interface. Builds on
:mod:`gaitbench.model`."""
