//! guiding
