//! Integration tests (one binary links faster).

mod cli;
mod common;
mod dataset;
mod evaluation;
mod recovery;
