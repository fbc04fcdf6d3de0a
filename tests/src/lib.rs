//! Cross-crate integration tests for Nebula; the tests live in `tests/tests/`.
