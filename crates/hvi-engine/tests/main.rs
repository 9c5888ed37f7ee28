//! The engine's integration tests, one test binary (docs/testing.md): the physics of an impact
//! ([`physics`]) and the quarter-symmetric scene against the full one ([`symmetry`]). Each
//! imports nothing but the engine.

mod physics;
mod symmetry;
