"""Experiments: one module per notebook's study; each function returns one table's unrounded DataFrame.
``default_choice`` (``make default-choice``) is the study that chose the named default's knobs on
notebook 13's target streams (``leaderboard.prepare``, ``target_protocols``).

They sit above ``methods/``, ``speed/`` and ``study/`` (they may import them) and below
``detect`` and ``cli``; nothing below imports them (``greenloop.architecture``).
"""
