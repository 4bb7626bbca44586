//! passangle end-to-end scenarios across crates live in `tests/tests/`; this library holds their
//! shared helpers.
