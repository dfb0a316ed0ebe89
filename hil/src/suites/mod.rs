//! Suites of runs with a verdict per row: the fault matrix ([`faults`]), the turntable's
//! validation ([`validate`]), fuzzing nav's inputs ([`fuzz`]) and the benchmarks ([`benchmarks`]).

pub mod benchmarks;
pub mod faults;
pub mod fuzz;
pub mod validate;
