//! The C API's constructors: the options struct and its defaults, and the engines made from a
//! site file.

use super::*;

/// Fills `*out` with the default options: the default transition model and fixed lag, a step
/// length of 0.7 m, the site file's north (NaN declination and rotation), no salt, the Viterbi
/// track kept. Call it before setting the fields you need, so that fields a later version adds
/// get their defaults too.
#[no_mangle]
pub extern "C" fn waymark_engine_options_default(out: *mut waymark_engine_options) -> waymark_result {
    boundary(|| {
        if out.is_null() {
            return fail(waymark_result::NullParameter, "out must not be NULL");
        }
        let defaults = ::waymark_engine::EngineConfig::default();
        write(
            out,
            waymark_engine_options {
                transition: waymark_transition::Default as u32,
                fixed_lag_epochs: u32::try_from(defaults.fixed_lag_epochs).unwrap_or(u32::MAX),
                step_length_m: f64::NAN,
                declination_deg: f64::NAN,
                site_rotation_deg: f64::NAN,
                site_salt: std::ptr::null(),
                site_salt_len: 0,
                track: u8::from(defaults.track),
            },
        );
        waymark_result::Ok
    })
}

/// The options both FFIs share, from C's; NULL for the defaults.
fn options_arg(options: *const waymark_engine_options) -> Result<Options, waymark_result> {
    // SAFETY: a non-NULL `options` points to one initialised waymark_engine_options (the
    // header's contract).
    let Some(o) = (unsafe { options.as_ref() }) else {
        return Ok(Options::default());
    };
    // The header's `waymark_transition` values, which C passes as a plain integer.
    let transition = match o.transition {
        t if t == waymark_transition::Default as u32 => None,
        t if t == waymark_transition::Reach as u32 => Some(TransitionModel::Reach),
        t if t == waymark_transition::Hipe as u32 => Some(TransitionModel::Regions),
        t if t == waymark_transition::Hoang as u32 => Some(TransitionModel::MovementVector),
        t => return Err(fail(waymark_result::InvalidConfig, format!("transition {t} does not exist"))),
    };
    let salt = match (o.site_salt.is_null(), o.site_salt_len) {
        (true, 0) => None,
        (true, _) => {
            return Err(fail(
                waymark_result::NullParameter,
                "site_salt must not be NULL when site_salt_len > 0",
            ))
        }
        // SAFETY: a non-NULL `site_salt` points to `site_salt_len` readable bytes (the header's
        // contract); they are copied here.
        (false, len) => Some(unsafe { std::slice::from_raw_parts(o.site_salt, len) }.to_vec()),
    };
    let track = match o.track {
        0 => false,
        1 => true,
        t => return Err(fail(waymark_result::InvalidConfig, format!("track must be 0 or 1, not {t}"))),
    };
    let given = |v: f64| (!v.is_nan()).then_some(v);
    Ok(Options {
        transition,
        fixed_lag_epochs: Some(o.fixed_lag_epochs as usize),
        track: Some(track),
        declination_deg: given(o.declination_deg),
        site_rotation_deg: given(o.site_rotation_deg),
        site_salt: salt,
        step_length_m: given(o.step_length_m),
    })
}

fn create(
    site: Result<Site, ::waymark_engine::SiteError>,
    options: &Options,
    out: *mut *mut waymark_engine,
) -> waymark_result {
    let handle = site.map_err(PositioningError::from).and_then(|site| {
        let site = Arc::new(site);
        Handle::new(site, options, Callbacks::default())
    });
    match handle {
        Ok(handle) => {
            write(out, Box::into_raw(Box::new(waymark_engine::new(handle))));
            waymark_result::Ok
        }
        Err(e) => fail_with(&e),
    }
}

/// Creates an engine from a site file's contents, `len` bytes at `site_file`: the binary
/// encoding (what an app should ship: it loads faster and in less memory,
/// docs/site-files.md#binary-encoding) or JSON text (not necessarily NUL-terminated), with `options`
/// (NULL for the defaults; see `waymark_engine_options_default`). On success `*out` holds the
/// engine; free it with `waymark_engine_free`. A site file on disk: read it into memory first.
#[no_mangle]
pub extern "C" fn waymark_engine_new_with_options(
    site_file: *const u8,
    len: usize,
    options: *const waymark_engine_options,
    out: *mut *mut waymark_engine,
) -> waymark_result {
    boundary(|| {
        if site_file.is_null() || out.is_null() {
            return fail(waymark_result::NullParameter, "site_file and out must not be NULL");
        }
        let options = match options_arg(options) {
            Ok(options) => options,
            Err(code) => return code,
        };
        // SAFETY: the caller guarantees `site_file` points to `len` readable bytes.
        let bytes = unsafe { std::slice::from_raw_parts(site_file, len) };
        create(Site::from_bytes(bytes), &options, out)
    })
}

/// The salt arguments of the deprecated constructors as options.
fn salt_options(salt: *const u8, salt_len: usize) -> waymark_engine_options {
    let mut options = std::mem::MaybeUninit::uninit();
    let _ = waymark_engine_options_default(options.as_mut_ptr());
    // SAFETY: `waymark_engine_options_default` wrote the whole struct (its pointer is not NULL).
    let options = unsafe { options.assume_init() };
    waymark_engine_options { site_salt: salt, site_salt_len: salt_len, ..options }
}

fn new_from_path(
    path: *const c_char,
    salt: *const u8,
    salt_len: usize,
    out: *mut *mut waymark_engine,
) -> waymark_result {
    boundary(|| {
        if path.is_null() || out.is_null() {
            return fail(waymark_result::NullParameter, "path and out must not be NULL");
        }
        let options = match options_arg(&salt_options(salt, salt_len)) {
            Ok(options) => options,
            Err(code) => return code,
        };
        // SAFETY: the caller guarantees a NUL-terminated string at `path`.
        let Ok(path) = unsafe { CStr::from_ptr(path) }.to_str() else {
            return fail(waymark_result::InvalidUtf8, "path is not UTF-8");
        };
        create(Site::load(path), &options, out)
    })
}

/// Deprecated: `waymark_engine_new_with_options` with NULL options does the same. Creates an
/// engine from a site file's contents (binary or JSON), `len` bytes at `site_file`.
#[no_mangle]
pub extern "C" fn waymark_engine_new(
    site_file: *const u8,
    len: usize,
    out: *mut *mut waymark_engine,
) -> waymark_result {
    waymark_engine_new_with_options(site_file, len, std::ptr::null(), out)
}

/// Deprecated: read the file and call `waymark_engine_new_with_options`. Creates an engine
/// from the site file (binary or JSON) at the NUL-terminated `path`.
#[no_mangle]
pub extern "C" fn waymark_engine_new_from_path(
    path: *const c_char,
    out: *mut *mut waymark_engine,
) -> waymark_result {
    new_from_path(path, std::ptr::null(), 0, out)
}

/// Deprecated: `waymark_engine_new_with_options` with `site_salt` and `site_salt_len` set
/// does the same. As `waymark_engine_new`, for a site file whose transmitter ids are salted
/// hashes: `salt` points to `salt_len` bytes, as `waymark_engine_options.site_salt`.
#[no_mangle]
pub extern "C" fn waymark_engine_new_with_salt(
    site_file: *const u8,
    len: usize,
    salt: *const u8,
    salt_len: usize,
    out: *mut *mut waymark_engine,
) -> waymark_result {
    boundary(|| waymark_engine_new_with_options(site_file, len, &salt_options(salt, salt_len), out))
}

/// Deprecated: read the file and call `waymark_engine_new_with_options` with the salt in the
/// options. As `waymark_engine_new_from_path`, with the site's salt as in
/// `waymark_engine_new_with_salt`.
#[no_mangle]
pub extern "C" fn waymark_engine_new_from_path_with_salt(
    path: *const c_char,
    salt: *const u8,
    salt_len: usize,
    out: *mut *mut waymark_engine,
) -> waymark_result {
    new_from_path(path, salt, salt_len, out)
}
