//! Secrets at rest: a policy endpoint's bearer token is stored sealed, never as
//! plain text, so a copied database or backup does not hand out participants' credentials.
//!
//! Policy:
//! - tokens are sealed with ChaCha20-Poly1305 (AEAD; `ring`, already in the tree for TLS) under
//!   the server's 32-byte secret key, a fresh random 96-bit nonce per sealing, and a fixed
//!   associated data string naming the purpose, so a sealed value cannot be replayed as
//!   another kind of secret;
//! - a sealed value reads `kr1.<key fingerprint>.<hex(nonce ‖ ciphertext ‖ tag)>`: the
//!   fingerprint (16 hex digits of a hash of the key, never the key) lets a server tell "sealed
//!   under another key" from "damaged", and say which;
//! - the key lives in a file (64 hex digits) that the server creates at first start with mode
//!   0600 (`[secrets] key_file`, default `secret.key` beside the database file); an in-memory
//!   database gets a key of its own per process. Losing the key loses the stored tokens (the
//!   runs already evaluated keep their results; re-simulating needs the token again), so a
//!   backup of the database must be paired with the key file, kept apart from it;
//! - opening never falls back to an empty token: a wrong key or a damaged value is an error
//!   that says so.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use ring::aead::{Aad, CHACHA20_POLY1305, LessSafeKey, NONCE_LEN, Nonce, UnboundKey};
use sha2::{Digest, Sha256};

/// Associated data of every sealed token: binds the ciphertext to its purpose.
const AAD: &[u8] = b"kitchen-r policy endpoint bearer token v1";
const PREFIX: &str = "kr1";
const KEY_BYTES: usize = 32;

/// Why a key could not be loaded or a sealed value opened.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub(crate) enum SecretError {
    #[error("secret key file {path}: {message}")]
    KeyFile { path: PathBuf, message: String },
    #[error(
        "a stored endpoint token was sealed with secret key {sealed_with}, but this server's key \
         is {ours}: the key file was replaced or belongs to another database (restore the \
         original key file, `[secrets] key_file`)"
    )]
    WrongKey { sealed_with: String, ours: String },
    #[error("a stored endpoint token cannot be opened with this server's secret key: {0}")]
    Damaged(&'static str),
}

/// The server's secret key.
#[derive(Clone)]
pub(crate) struct SecretKey {
    key: LessSafeKey,
    fingerprint: String,
}

impl std::fmt::Debug for SecretKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never the key itself.
        f.debug_struct("SecretKey")
            .field("fingerprint", &self.fingerprint)
            .finish_non_exhaustive()
    }
}

impl SecretKey {
    /// A fresh random key (an in-memory database's, or a new key file's).
    pub(crate) fn generate() -> SecretKey {
        SecretKey::from_bytes(&rand::random::<[u8; KEY_BYTES]>())
    }

    fn from_bytes(bytes: &[u8; KEY_BYTES]) -> SecretKey {
        // CHACHA20_POLY1305 takes exactly 32 bytes, which the array type guarantees.
        let unbound = UnboundKey::new(&CHACHA20_POLY1305, bytes).expect("a 32-byte key");
        let mut h = Sha256::new();
        h.update(b"kitchen-r secret key fingerprint\0");
        h.update(bytes);
        SecretKey {
            key: LessSafeKey::new(unbound),
            fingerprint: hex::encode(&h.finalize()[..8]),
        }
    }

    /// The key in `path`, or a new one written there (mode 0600) when the file does not exist.
    pub(crate) fn load_or_create(path: &Path) -> Result<SecretKey, SecretError> {
        let err = |message: String| SecretError::KeyFile {
            path: path.to_path_buf(),
            message,
        };
        match std::fs::read_to_string(path) {
            Ok(text) => return SecretKey::parse(text.trim()).map_err(err),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(err(format!("cannot be read: {e}"))),
        }
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| err(format!("cannot create its directory: {e}")))?;
        }
        let bytes: [u8; KEY_BYTES] = rand::random();
        let mut options = std::fs::OpenOptions::new();
        options.write(true).create_new(true);
        #[cfg(unix)]
        std::os::unix::fs::OpenOptionsExt::mode(&mut options, 0o600);
        match options.open(path) {
            Ok(mut file) => {
                writeln!(file, "{}", hex::encode(bytes))
                    .and_then(|()| file.sync_all())
                    .map_err(|e| err(format!("cannot be written: {e}")))?;
                tracing::info!(path = %path.display(), "created the secret key file (mode 0600)");
                Ok(SecretKey::from_bytes(&bytes))
            }
            // Another process created it first: use theirs.
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => SecretKey::load_or_create(path),
            Err(e) => Err(err(format!("cannot be created: {e}"))),
        }
    }

    fn parse(text: &str) -> Result<SecretKey, String> {
        let bytes = hex::decode(text)
            .ok()
            .and_then(|b| <[u8; KEY_BYTES]>::try_from(b).ok());
        bytes
            .map(|b| SecretKey::from_bytes(&b))
            .ok_or_else(|| format!("must hold {} hex digits (a 32-byte key)", 2 * KEY_BYTES))
    }

    /// 16 hex digits naming this key (not revealing it).
    pub(crate) fn fingerprint(&self) -> &str {
        &self.fingerprint
    }

    /// `plain` sealed under this key.
    pub(crate) fn seal(&self, plain: &str) -> String {
        let nonce: [u8; NONCE_LEN] = rand::random();
        let mut buf = plain.as_bytes().to_vec();
        // Sealing fails only for inputs of gigabytes; tokens are at most a few KiB.
        self.key
            .seal_in_place_append_tag(Nonce::assume_unique_for_key(nonce), Aad::from(AAD), &mut buf)
            .expect("sealing a short token");
        let mut out = nonce.to_vec();
        out.extend_from_slice(&buf);
        format!("{PREFIX}.{}.{}", self.fingerprint, hex::encode(out))
    }

    /// The plain text of a value [`SecretKey::seal`] made.
    pub(crate) fn open(&self, sealed: &str) -> Result<String, SecretError> {
        let mut parts = sealed.splitn(3, '.');
        let (Some(PREFIX), Some(fingerprint), Some(data)) = (parts.next(), parts.next(), parts.next()) else {
            return Err(SecretError::Damaged("not a sealed value"));
        };
        if fingerprint != self.fingerprint {
            return Err(SecretError::WrongKey {
                sealed_with: fingerprint.to_string(),
                ours: self.fingerprint.clone(),
            });
        }
        let mut data = hex::decode(data).map_err(|_| SecretError::Damaged("not hex"))?;
        if data.len() < NONCE_LEN {
            return Err(SecretError::Damaged("too short"));
        }
        let mut body = data.split_off(NONCE_LEN);
        let nonce =
            <[u8; NONCE_LEN]>::try_from(data.as_slice()).map_err(|_| SecretError::Damaged("no nonce"))?;
        let plain = self
            .key
            .open_in_place(Nonce::assume_unique_for_key(nonce), Aad::from(AAD), &mut body)
            .map_err(|_| SecretError::Damaged("authentication failed (altered, or another key)"))?;
        String::from_utf8(plain.to_vec()).map_err(|_| SecretError::Damaged("not UTF-8"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sealed_tokens_open_with_their_key_only_and_never_show_the_plain_text() {
        let key = SecretKey::generate();
        let sealed = key.seal("participant-secret");
        assert!(!sealed.contains("participant-secret") && sealed.starts_with("kr1."));
        assert_ne!(
            sealed,
            key.seal("participant-secret"),
            "a fresh nonce per sealing"
        );
        assert_eq!(key.open(&sealed).unwrap(), "participant-secret");
        let other = SecretKey::generate();
        assert!(matches!(other.open(&sealed), Err(SecretError::WrongKey { .. })));
        // Same fingerprint, altered ciphertext: refused, never an empty or wrong token.
        let mut altered = sealed.clone();
        let last = altered.pop().unwrap();
        altered.push(if last == '0' { '1' } else { '0' });
        assert!(matches!(key.open(&altered), Err(SecretError::Damaged(_))));
        assert!(matches!(key.open("s3cret"), Err(SecretError::Damaged(_))));
    }

    #[test]
    fn the_key_file_is_created_once_with_mode_0600_and_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub/secret.key");
        let key = SecretKey::load_or_create(&path).unwrap();
        let again = SecretKey::load_or_create(&path).unwrap();
        assert_eq!(key.fingerprint(), again.fingerprint());
        assert_eq!(again.open(&key.seal("t")).unwrap(), "t");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&path).unwrap().permissions().mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        std::fs::write(&path, "not a key\n").unwrap();
        let e = SecretKey::load_or_create(&path).unwrap_err();
        assert!(e.to_string().contains("64 hex digits"), "{e}");
    }
}
