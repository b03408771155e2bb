#!/usr/bin/env python3
"""Prints the seed-0 NumPy permutation of the 100 NeRF-synthetic training frames.

DietNeRF-style sparse-view NeRF-synthetic experiments (reused by FreeNeRF and others) take the
first n entries of `np.random.seed(0); np.random.permutation(100)` as the n training views.
`crates/scene/src/split.rs` commits the whole permutation as the constant
`BLENDER_SPARSE_PERMUTATION`; this script is the reference that produced it.

Rerun (NumPy's legacy RandomState stream is frozen, so any NumPy version gives the same output):
    python3 -m venv tools/.venv && tools/.venv/bin/pip install numpy
    tools/.venv/bin/python tools/blender_sparse_permutation.py
"""

import numpy as np

np.random.seed(0)
perm = np.random.permutation(100)
print("pub const BLENDER_SPARSE_PERMUTATION: [usize; 100] = [")
for row in range(0, 100, 10):
    print("    " + ", ".join(str(int(v)) for v in perm[row : row + 10]) + ",")
print("];")
