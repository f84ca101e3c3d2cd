"""Benchmarks and studies of diffcloth-gym, kept outside the package: they time and stress the
simulator, they are not part of it. Results go to ``benchmarks/results/<name>.{json,md}``.

Run from the repository root: ``python -m benchmarks <study> [options]`` (see
:mod:`benchmarks.__main__`), or the thin entry points ``scripts/bench_step.py`` and
``scripts/bench_backward.py``.
"""
