"""Built-in experiment plugins: the thesis terrains, the energetics study, the compass gait, the biped models."""
