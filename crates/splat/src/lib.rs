//! 3D Gaussian splatting: model, rasterizer, training.
