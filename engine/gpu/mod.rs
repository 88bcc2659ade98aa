//! The Vulkan device layer: the only module that uses `ash`.
