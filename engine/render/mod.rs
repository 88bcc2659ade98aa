//! Rendering: camera, GPU SVDAG traversal and its CPU reference.
