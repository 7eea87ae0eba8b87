//! The keys file (`--auth-keys FILE`): one key per line, `TENANT ROLES
//! SHA256HEX`, `#` comments. The file holds only the SHA-256 of each key, so
//! a copy of it lets nobody in; a presented key is hashed and compared with
//! every line in constant time.

use super::Roles;
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use subtle::ConstantTimeEq;

/// Longest key accepted in a request, bytes (a longer one is wrong, unhashed).
const MAX_KEY_LEN: usize = 512;

/// Why a keys file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum KeysError {
    #[error("{}: {source}", path.display())]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}:{line}: {detail}", path.display())]
    Line {
        path: PathBuf,
        line: usize,
        detail: String,
    },
    #[error("{}: no keys (lines `TENANT ROLES SHA256HEX`; make one with `amc keys new TENANT ROLES`)", path.display())]
    Empty { path: PathBuf },
}

/// A tenant's name: 1-64 of `A-Z a-z 0-9 _ . -`, so it is safe as an object
/// prefix and a log field.
pub fn valid_tenant(name: &str) -> bool {
    (1..=64).contains(&name.len())
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"_.-".contains(&b))
        && name != "."
        && name != ".."
}

/// One line of the file.
#[derive(Clone, Debug)]
pub struct KeyEntry {
    pub tenant: String,
    pub roles: Roles,
    hash: [u8; 32],
}

/// Who a request is, once its key or ticket is accepted.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Principal {
    pub tenant: String,
    pub roles: Roles,
    /// The key's line in the file (per-key rate limits); `None` without keys.
    pub key: Option<usize>,
}

impl Principal {
    /// Everyone, when the service runs without keys (loopback only).
    pub fn local() -> Self {
        Self {
            tenant: "local".into(),
            roles: Roles::ALL,
            key: None,
        }
    }
}

/// The parsed keys file.
#[derive(Clone, Debug)]
pub struct KeyTable {
    entries: Vec<KeyEntry>,
}

/// SHA-256 of a key, as the file holds it.
pub fn hash_key(key: &str) -> [u8; 32] {
    Sha256::digest(key.as_bytes()).into()
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn parse_hex32(s: &str) -> Option<[u8; 32]> {
    if s.len() != 64 || !s.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    let mut out = [0u8; 32];
    for (i, o) in out.iter_mut().enumerate() {
        *o = u8::from_str_radix(&s[2 * i..2 * i + 2], 16).ok()?;
    }
    Some(out)
}

/// What every key `generate_key` makes starts with.
pub const KEY_PREFIX: &str = "amc_";

impl KeyTable {
    /// Parses the file's text; `path` only names it in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, KeysError> {
        let mut entries: Vec<KeyEntry> = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let bad = |detail: String| KeysError::Line {
                path: path.to_path_buf(),
                line: i + 1,
                detail,
            };
            let line = raw.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            let fields: Vec<&str> = line.split_whitespace().collect();
            let [tenant, roles, hash] = fields[..] else {
                return Err(bad(format!(
                    "{} fields (allowed: 3, `TENANT ROLES SHA256HEX`)",
                    fields.len()
                )));
            };
            if !valid_tenant(tenant) {
                return Err(bad(format!(
                    "tenant {tenant:?} (allowed: 1-64 of A-Z, a-z, 0-9, '_', '.', '-')"
                )));
            }
            let roles = Roles::parse(roles).map_err(bad)?;
            // The field is never echoed: a key pasted where its hash goes
            // would otherwise end up in the service's log.
            let hash = parse_hex32(hash).ok_or_else(|| {
                let looks_like_key = if hash.starts_with(KEY_PREFIX) {
                    "; it looks like a key itself: put `amc keys new`'s file line here, not the key"
                } else {
                    ""
                };
                bad(format!(
                    "the hash field ({} characters, not shown) is not 64 hex digits (the SHA-256 of the key){looks_like_key}",
                    hash.chars().count()
                ))
            })?;
            if entries.iter().any(|e| e.hash == hash) {
                return Err(bad("the same key hash is on an earlier line".into()));
            }
            entries.push(KeyEntry {
                tenant: tenant.to_string(),
                roles,
                hash,
            });
        }
        if entries.is_empty() {
            return Err(KeysError::Empty {
                path: path.to_path_buf(),
            });
        }
        Ok(Self { entries })
    }

    /// Reads and parses the file.
    pub fn load(path: &Path) -> Result<Self, KeysError> {
        let text = std::fs::read_to_string(path).map_err(|source| KeysError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path)
    }

    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The key's principal, or `None`. Every line is compared, in constant
    /// time, whatever matches: the time taken says nothing of the key.
    pub fn lookup(&self, key: &str) -> Option<Principal> {
        if key.is_empty() || key.len() > MAX_KEY_LEN {
            return None;
        }
        let hash = hash_key(key);
        let mut found: Option<usize> = None;
        for (i, e) in self.entries.iter().enumerate() {
            if bool::from(e.hash.ct_eq(&hash)) {
                found = Some(i);
            }
        }
        found.map(|i| Principal {
            tenant: self.entries[i].tenant.clone(),
            roles: self.entries[i].roles,
            key: Some(i),
        })
    }
}

/// A fresh key and its line for the keys file (`amc keys new`): 256 random
/// bits from the OS, `amc_` and 64 hex digits.
pub fn new_key(tenant: &str, roles: &str) -> Result<(String, String), String> {
    use rand::RngCore;
    if !valid_tenant(tenant) {
        return Err(format!(
            "invalid tenant {tenant:?} (allowed: 1-64 of A-Z, a-z, 0-9, '_', '.', '-')"
        ));
    }
    let roles = Roles::parse(roles)?;
    let mut bytes = [0u8; 32];
    rand::rngs::OsRng.fill_bytes(&mut bytes);
    let key = format!("{KEY_PREFIX}{}", hex(&bytes));
    let line = format!("{tenant} {roles} {}", hex(&hash_key(&key)));
    Ok((key, line))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(text: &str) -> Result<KeyTable, KeysError> {
        KeyTable::parse(text, Path::new("keys"))
    }

    #[test]
    fn a_new_key_is_found_by_its_line_and_nothing_else_is() {
        let (key, line) = new_key("alice", "submit,view").unwrap();
        assert!(key.starts_with("amc_") && key.len() == 68);
        assert!(!line.contains(&key));
        let (other, other_line) = new_key("bob", "admin").unwrap();
        let t = table(&format!("# comment\n\n{line}\n{other_line} # trailing\n")).unwrap();
        let alice = t.lookup(&key).unwrap();
        assert_eq!(alice.tenant, "alice");
        assert!(alice.roles.has(Roles::SUBMIT) && alice.roles.has(Roles::VIEW));
        assert!(!alice.roles.has(Roles::PUBLISH) && !alice.roles.has(Roles::ADMIN));
        assert_eq!(t.lookup(&other).unwrap().tenant, "bob");
        assert!(t.lookup("").is_none());
        assert!(t.lookup(&key[..67]).is_none());
        assert!(t.lookup(&format!("{key} ")).is_none());
        assert!(t.lookup(&"x".repeat(10_000)).is_none());
    }

    #[test]
    fn bad_lines_name_their_line_and_what_is_allowed() {
        let h = "a".repeat(64);
        for (text, needle) in [
            (format!("alice submit\n"), "2 fields"),
            (format!("al/ice submit {h}\n"), "tenant"),
            (format!("alice root {h}\n"), "unknown role"),
            (
                format!("alice submit {}\n", "a".repeat(63)),
                "64 hex digits",
            ),
            (format!("alice submit {h}\nbob view {h}\n"), "earlier line"),
            ("# nothing\n".to_string(), "no keys"),
        ] {
            let e = table(&text).unwrap_err().to_string();
            assert!(e.contains(needle), "{text:?}: {e}");
        }
        let e = table(&format!("\nalice root {h}\n"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("keys:2:"), "{e}");
    }

    #[test]
    fn tenant_names_are_safe_as_prefixes() {
        for ok in ["a", "team-7", "A.b_c"] {
            assert!(valid_tenant(ok), "{ok}");
        }
        for bad in ["", ".", "..", "a/b", "a b", &"x".repeat(65), "é"] {
            assert!(!valid_tenant(bad), "{bad}");
        }
    }
}
