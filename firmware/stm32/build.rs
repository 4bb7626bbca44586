//! Linker arguments for cortex-m-rt (`link.x`, memory.x from embassy's `memory-x` feature) and defmt.
fn main() {
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
