"""Experiments and studies: configs, evaluation, EXP1, transfer matrix, benchmarks, plots."""
