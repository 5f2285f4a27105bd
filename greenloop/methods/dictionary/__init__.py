"""The main paper (Qi 2024): spots of L frames, the one-conv-layer CNN, shifts of its inputs,
the frequency dictionary with tau = L + Delta, its streaming detector and its registry entry."""
