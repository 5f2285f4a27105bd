"""One home per method: each folder holds a method's stages, its streaming detector and its
registry entry (``entry.py``); ``interface`` is the record every entry fills, ``registry`` the one
list the leaderboard, ``detect`` and the tests read."""
