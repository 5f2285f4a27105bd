"""Xu 2022's Siamese CNN with three supervisions and three RGB-D fusions, and its registry entry."""
