"""One module per experiment: functions per table returning unrounded DataFrames and figure data.

Experiments sit above the stages, ``speed/``, ``detectors/`` and ``study/`` (they may import them)
and below ``__main__``; nothing below imports them.
"""
