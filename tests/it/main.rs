//! Integration tests (one binary links faster).

mod common;
mod recovery;
