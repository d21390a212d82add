//! uniffi's binding generator, pinned to the crate's uniffi version:
//! `cargo run --features bindgen --bin uniffi-bindgen -- generate --library target/debug/libwaymark.so --language kotlin --out-dir target/bindings/kotlin --no-format`.

fn main() {
    uniffi::uniffi_bindgen_main()
}
