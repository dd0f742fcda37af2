//! Integration tests (one binary links faster).

mod adversarial;
mod alloc;
mod architecture;
mod benchmarks;
mod cli;
mod common;
mod dataset;
mod evaluation;
mod groundtruth;
#[cfg(feature = "gui")]
mod gui;
mod landscape;
mod patches;
mod recovery;
mod report;
mod robustness;
mod whole;

#[global_allocator]
static ALLOCATOR: alloc::Counting = alloc::Counting;
