"""Benchmarks: results go to benchmarks/results/<name>.{json,md} (DESIGN.md section 6)."""
