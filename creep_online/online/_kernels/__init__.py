"""Numba kernels of the online trackers and their state layout (private: the trackers and the estimator use them)."""
