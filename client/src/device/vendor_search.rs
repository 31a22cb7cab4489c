//! Where a vendor's library is looked for, and which candidate is taken: the search both run-time-loaded
//! SDKs (DHD, OpenHaptics) share. The user's variable naming the file wins alone; then each library name in
//! the SDK's folder (`$SDK/lib`), then in the usual system folders, then bare (the system loader's own
//! search path). The first candidate that exists and loads is taken; a candidate that exists but is refused
//! is the answer (its error), so a broken install is said rather than skipped.

use std::path::{Path, PathBuf};

/// The candidates, in order (see the module documentation).
pub fn candidates(file_variable: &str, sdk_variable: &str, system_folders: &[&str], names: &[&str]) -> Vec<PathBuf> {
    if let Some(path) = std::env::var_os(file_variable).filter(|p| !p.is_empty()) {
        return vec![PathBuf::from(path)];
    }
    let mut folders = Vec::new();
    if let Some(sdk) = std::env::var_os(sdk_variable).filter(|p| !p.is_empty()) {
        folders.push(PathBuf::from(sdk).join("lib"));
    }
    if !cfg!(windows) {
        folders.extend(system_folders.iter().map(PathBuf::from));
    }
    let mut found: Vec<PathBuf> = folders.iter().flat_map(|f| names.iter().map(move |n| f.join(n))).collect();
    found.extend(names.iter().map(PathBuf::from));
    found
}

/// The first of `candidates` that `load` takes; a bare name the loader cannot load (`not_loadable`) is
/// passed over, as is a path that does not exist. None when no candidate answered.
pub fn first_loadable<L, E>(
    candidates: &[PathBuf],
    load: impl Fn(&Path) -> Result<L, E>,
    not_loadable: impl Fn(&E) -> bool,
) -> Option<Result<L, E>> {
    for path in candidates {
        // A bare name goes to the system loader's search; a path must exist.
        let bare = path.components().count() == 1;
        if !bare && !path.exists() {
            continue;
        }
        match load(path) {
            Err(e) if bare && not_loadable(&e) => continue,
            result => return Some(result),
        }
    }
    None
}

/// The symbol `name` of `library` as a `T`, or None with `name` added to `missing`.
///
/// # Safety
/// `T` must be the type the library's header declares for `name` (a function pointer of its signature).
pub unsafe fn required<T: Copy>(
    library: &libloading::Library,
    name: &'static str,
    missing: &mut Vec<&'static str>,
) -> Option<T> {
    // SAFETY: as this function's contract.
    let found = unsafe { optional(library, name) };
    if found.is_none() {
        missing.push(name);
    }
    found
}

/// The symbol `name` of `library` as a `T`, when it has it.
///
/// # Safety
/// As [`required`].
pub unsafe fn optional<T: Copy>(library: &libloading::Library, name: &'static str) -> Option<T> {
    // SAFETY: as this function's contract.
    unsafe { library.get::<T>(name) }.ok().map(|symbol| *symbol)
}
