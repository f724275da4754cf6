"""Comparison with Cycles (bpy-free): metrics, reference cache, cost/accuracy sweep, report."""
