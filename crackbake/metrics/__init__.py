"""Measures of a crack network read from its polylines: what the realism goals are stated in.

``star`` (radial arms, straightness, concentric links of an impact), ``cells`` (cell area,
width, straightness and junction angles of a preset's network) and ``growth`` (how connected
the network revealed by ``crack.time`` is at each moment).  Plain functions over arrays; the
tests and ``benchmarks/bench_realism.py`` state the goals in them.
"""
