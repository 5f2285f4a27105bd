"""Random-hyperplane LSH with SWP / QDP multi-probing (Qi 2024), and candidate retrieval on an
index (exact scan, faiss flat / IVF / HNSW, the paper's RHLSH)."""
