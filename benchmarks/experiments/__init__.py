"""Experiments on the thesis's perception, apart from the timing scripts: each a module run
from the repository root (``python -m benchmarks.experiments.<name>``).

- :mod:`~benchmarks.experiments.realistic_flow`: motion correlation with the CPU flow on
  recorded, noisy, perturbed scenes (``record``, then ``evaluate``);
- ``compare_methods``: correlation against segmentation and the ablation;
- ``compare_published``: cablesim's motion correlation against the published code's;
- ``published_reference``: the published code's maps of a synthetic stream, for the tests.
"""
