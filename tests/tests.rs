//! Integration tests of the renderer, one binary with a module per concern (as ripgrep does).

mod api;
mod common;
mod furnace;
mod guided;
mod mitsuba;
mod render;
mod single_scatter;
mod tracking;
mod transmittance;
mod vdb;
mod xml;
