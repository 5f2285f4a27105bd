"""Experiments: one module per notebook's study; each function returns one table's unrounded DataFrame.

They sit above the stages, ``speed/``, ``detectors/`` and ``study/`` (they may import them) and below
``__main__``; nothing below imports them.
"""
