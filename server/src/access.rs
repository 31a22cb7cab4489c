//! Who may join: tokens from a file, each optionally limited to a role, compared in constant time.
//!
//! File format (`--token-file`): one token per line, optionally followed by whitespace and a role
//! (`manipulator` or `observer`); blank lines and `#` comments are ignored:
//! ```text
//! # lab members
//! 3f9c2e7a…            # any role
//! 81d0b5c4…  observer  # may only watch
//! ```
//! A token without a role may join as either; `manipulator` also allows observing; `observer` only
//! observing. Tokens are kept as SHA-256 digests and every check compares the candidate's digest with
//! *every* entry without early exit, so timing reveals neither which token nor how much of one matched.
//! Tokens never appear in logs or `Debug` output.

use std::fmt;
use std::path::{Path, PathBuf};

use kinloop_protocol::{RefusalReason, Role};
use subtle::{Choice, ConstantTimeEq};

/// A digest of a token.
type Digest = [u8; 32];

fn digest(token: &str) -> Digest {
    let mut out = [0u8; 32];
    out.copy_from_slice(ring::digest::digest(&ring::digest::SHA256, token.as_bytes()).as_ref());
    out
}

/// One allowed token.
#[derive(Clone)]
struct Entry {
    digest: Digest,
    role: Option<Role>,
}

/// The server's access rule: any token ([`Access::open`], when no token file is given; the server warns
/// once at start) or only the listed ones.
#[derive(Clone)]
pub struct Access {
    tokens: Option<Vec<Entry>>,
}

impl fmt::Debug for Access {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.tokens {
            None => f.write_str("Access(open)"),
            Some(entries) => write!(f, "Access({} tokens, redacted)", entries.len()),
        }
    }
}

/// A token file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum AccessError {
    /// It could not be read.
    #[error("cannot read token file {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A line names a role that does not exist (the token itself is not repeated).
    #[error("{file}:{line}: unknown role {role:?} (expected manipulator or observer)")]
    UnknownRole {
        /// The file.
        file: String,
        /// 1-based line number.
        line: usize,
        /// What was written.
        role: String,
    },
    /// A line has more than a token and a role.
    #[error("{file}:{line}: expected `TOKEN` or `TOKEN ROLE`")]
    Malformed {
        /// The file.
        file: String,
        /// 1-based line number.
        line: usize,
    },
    /// The file lists no token at all, which would lock everyone out.
    #[error("{file}: no tokens (remove --token-file to accept any token)")]
    Empty {
        /// The file.
        file: String,
    },
}

impl Access {
    /// Reads a token file.
    pub fn from_file(path: &Path) -> Result<Access, AccessError> {
        let text =
            std::fs::read_to_string(path).map_err(|source| AccessError::Read { path: path.to_owned(), source })?;
        Access::parse(&text, &path.display().to_string())
    }

    /// Parses token-file text; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<Access, AccessError> {
        let mut entries = Vec::new();
        for (index, raw) in text.lines().enumerate() {
            let line = raw.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            let mut words = line.split_whitespace();
            let (Some(token), role, None) = (words.next(), words.next(), words.next()) else {
                return Err(AccessError::Malformed { file: file.to_owned(), line: index + 1 });
            };
            let role = match role {
                None => None,
                Some("manipulator") => Some(Role::Manipulator),
                Some("observer") => Some(Role::Observer),
                Some(other) => {
                    return Err(AccessError::UnknownRole { file: file.to_owned(), line: index + 1, role: other.into() })
                }
            };
            entries.push(Entry { digest: digest(token), role });
        }
        if entries.is_empty() {
            return Err(AccessError::Empty { file: file.to_owned() });
        }
        Ok(Access { tokens: Some(entries) })
    }

    /// Accepts any token.
    pub fn open() -> Access {
        Access { tokens: None }
    }

    /// Decides whether `token` may join as `role`: [`RefusalReason::BadToken`] for an unknown token (and
    /// nothing else: the client learns no more), [`RefusalReason::RoleNotAllowed`] for a known token asking
    /// for a role it does not have.
    pub fn admit(&self, token: &str, role: Role) -> Result<(), RefusalReason> {
        let Some(entries) = &self.tokens else {
            return Ok(());
        };
        let candidate = digest(token);
        let mut known = Choice::from(0);
        let mut allowed = Choice::from(0);
        for entry in entries {
            let matches = entry.digest.ct_eq(&candidate);
            let role_ok = match (entry.role, role) {
                (None, _) | (Some(Role::Manipulator), _) | (Some(Role::Observer), Role::Observer) => 1,
                (Some(Role::Observer), Role::Manipulator) => 0,
            };
            known |= matches;
            allowed |= matches & Choice::from(role_ok);
        }
        match (bool::from(known), bool::from(allowed)) {
            (false, _) => Err(RefusalReason::BadToken),
            (true, false) => Err(RefusalReason::RoleNotAllowed),
            (true, true) => Ok(()),
        }
    }

    /// True when any token is accepted.
    pub fn is_open(&self) -> bool {
        self.tokens.is_none()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = "
        # a comment line
        alpha-token
        bravo-token   observer   # only watches
        charlie-token manipulator
    ";

    #[test]
    fn tokens_and_roles_decide_admission() {
        let access = Access::parse(FILE, "tokens.txt").unwrap();
        assert_eq!(access.admit("alpha-token", Role::Manipulator), Ok(()));
        assert_eq!(access.admit("alpha-token", Role::Observer), Ok(()));
        assert_eq!(access.admit("bravo-token", Role::Observer), Ok(()));
        assert_eq!(access.admit("bravo-token", Role::Manipulator), Err(RefusalReason::RoleNotAllowed));
        assert_eq!(access.admit("charlie-token", Role::Observer), Ok(()));
        assert_eq!(access.admit("delta-token", Role::Observer), Err(RefusalReason::BadToken));
        assert_eq!(access.admit("", Role::Observer), Err(RefusalReason::BadToken));
        assert_eq!(access.admit("alpha-toke", Role::Observer), Err(RefusalReason::BadToken));
        assert_eq!(Access::open().admit("anything", Role::Manipulator), Ok(()));
    }

    #[test]
    fn token_files_with_mistakes_are_refused_without_echoing_tokens() {
        let error = Access::parse("secret-1 admin\n", "t.txt").unwrap_err();
        assert_eq!(error.to_string(), "t.txt:1: unknown role \"admin\" (expected manipulator or observer)");
        let error = Access::parse("secret-1 observer extra\n", "t.txt").unwrap_err();
        assert!(!error.to_string().contains("secret"));
        assert!(matches!(Access::parse("# nothing\n\n", "t.txt"), Err(AccessError::Empty { .. })));
        let debug = format!("{:?}", Access::parse("secret-1\n", "t.txt").unwrap());
        assert!(!debug.contains("secret"), "{debug}");
    }
}
