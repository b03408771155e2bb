//! Geometry toolbox (paper 000 §1–2, §4; paper 001 Alg. 3): see the modules.
