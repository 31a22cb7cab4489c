//! The `kinloop` command line.

pub mod bench;
pub mod demo;
pub mod devices;
pub mod devices_hd;
pub mod experiment;
pub mod export;
pub mod generate;
pub mod import;
pub mod inspect;
pub mod load;
pub mod simulate;
pub mod timer_floor;
pub mod view;

/// A `--users` value: a whole number from 1 to `max`.
pub(crate) fn parse_user_count(s: &str, max: usize) -> Result<usize, String> {
    let n: usize = s.parse().map_err(|_| format!("{s:?} is not a whole number"))?;
    if (1..=max).contains(&n) {
        Ok(n)
    } else {
        Err(format!("{n} users: between 1 and {max}"))
    }
}
