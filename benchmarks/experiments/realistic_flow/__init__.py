"""Realistic flow: motion correlation with the CPU flow on recorded, noisy, perturbed scenes
(``python -m benchmarks.experiments.realistic_flow record|evaluate``; the command is
``__main__``).  :mod:`.record` simulates and records the scenes, :mod:`.evaluate` runs the
perception variants on the recordings and scores them, :mod:`.report` writes the markdown."""
