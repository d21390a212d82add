//! uniffi's binding generator, pinned by Cargo.lock to the library's uniffi version:
//! `cargo uniffi-bindgen generate --library target/debug/libwaymark.so --language kotlin --out-dir DIR`.

fn main() {
    uniffi::uniffi_bindgen_main()
}
