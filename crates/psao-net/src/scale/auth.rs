//! How a trace node or an edge proves itself to the NATS server, and how it checks the
//! server: credentials (a `.creds` file, user and password, a token, or an NKey seed; secrets
//! are read from files, never taken on the command line) and TLS (a CA to trust, a client
//! certificate). Which subjects each account may publish is the NATS server's configuration
//! (docs/SCALE-OUT.md, "Accounts and permissions"); what a node accepts from the bus is
//! checked independently of it.

use std::path::{Path, PathBuf};

use async_nats::ConnectOptions;

use crate::{secret, NetError};

/// Longest secret file read (a `.creds` file is about 1 KiB).
const MAX_SECRET_FILE: u64 = 64 << 10;

/// Credentials and TLS settings for the NATS connection (all optional: none connects
/// anonymously, as a local `nats-server -js` allows).
#[derive(Clone, Debug, Default)]
pub struct NatsAuth {
    /// A NATS `.creds` file (user JWT and NKey seed).
    pub creds_file: Option<PathBuf>,
    /// User name, with [`NatsAuth::password_file`].
    pub user: Option<String>,
    /// File whose first line is the user's password.
    pub password_file: Option<PathBuf>,
    /// File whose first line is the NATS token.
    pub token_file: Option<PathBuf>,
    /// File whose first line is an NKey seed (`SU…`).
    pub nkey_seed_file: Option<PathBuf>,
    /// PEM certificates to trust for the server (turns TLS on).
    pub tls_ca: Option<PathBuf>,
    /// PEM client certificate, with [`NatsAuth::tls_key`] (turns TLS on).
    pub tls_cert: Option<PathBuf>,
    /// PEM private key of [`NatsAuth::tls_cert`].
    pub tls_key: Option<PathBuf>,
}

impl NatsAuth {
    /// Connection options carrying these credentials and TLS settings.
    pub async fn options(&self) -> Result<ConnectOptions, NetError> {
        let chosen = [
            self.creds_file.is_some(),
            self.user.is_some() || self.password_file.is_some(),
            self.token_file.is_some(),
            self.nkey_seed_file.is_some(),
        ];
        if chosen.iter().filter(|&&c| c).count() > 1 {
            return Err(config(
                "give one NATS credential: a creds file, a user and password, a token or an NKey seed",
            ));
        }
        let mut options = ConnectOptions::new();
        if let Some(path) = &self.creds_file {
            let text = read_secret(path)?;
            options = options
                .credentials(&text)
                .map_err(|e| config(&format!("NATS creds file {}: {e}", path.display())))?;
        }
        match (&self.user, &self.password_file) {
            (Some(user), Some(pass)) => {
                options = options.user_and_password(user.clone(), first_line(pass)?);
            }
            (None, None) => {}
            _ => return Err(config("--nats-user needs --nats-password-file and back")),
        }
        if let Some(path) = &self.token_file {
            options = options.token(first_line(path)?);
        }
        if let Some(path) = &self.nkey_seed_file {
            options = options.nkey(first_line(path)?);
        }
        if let Some(ca) = &self.tls_ca {
            check_file(ca)?;
            options = options.add_root_certificates(ca.clone()).require_tls(true);
        }
        match (&self.tls_cert, &self.tls_key) {
            (Some(cert), Some(key)) => {
                check_file(cert)?;
                check_file(key)?;
                options = options
                    .add_client_certificate(cert.clone(), key.clone())
                    .require_tls(true);
            }
            (None, None) => {}
            _ => return Err(config("--nats-tls-cert needs --nats-tls-key and back")),
        }
        Ok(options)
    }
}

fn config(message: &str) -> NetError {
    NetError::Config(message.to_owned())
}

fn check_file(path: &Path) -> Result<(), NetError> {
    secret::check(path, MAX_SECRET_FILE)
}

fn read_secret(path: &Path) -> Result<String, NetError> {
    secret::read(path, MAX_SECRET_FILE)
}

fn first_line(path: &Path) -> Result<String, NetError> {
    secret::first_line(path, MAX_SECRET_FILE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn credentials_are_read_from_files_and_conflicts_refused() {
        let dir = tempfile::tempdir().unwrap();
        let pass = dir.path().join("pass");
        std::fs::write(&pass, "hunter2\n").unwrap();
        let ok = NatsAuth {
            user: Some("edge".into()),
            password_file: Some(pass.clone()),
            ..NatsAuth::default()
        };
        assert!(ok.options().await.is_ok());
        let half = NatsAuth {
            user: Some("edge".into()),
            ..NatsAuth::default()
        };
        assert!(half.options().await.is_err());
        let two = NatsAuth {
            token_file: Some(pass.clone()),
            ..ok.clone()
        };
        assert!(two
            .options()
            .await
            .unwrap_err()
            .to_string()
            .contains("one NATS credential"));
        std::fs::write(&pass, "\n").unwrap();
        assert!(ok
            .options()
            .await
            .unwrap_err()
            .to_string()
            .contains("empty"));
        let missing = NatsAuth {
            tls_ca: Some(dir.path().join("nope.pem")),
            ..NatsAuth::default()
        };
        assert!(missing.options().await.is_err());
        let garbage = dir.path().join("bad.creds");
        std::fs::write(&garbage, "not a creds file").unwrap();
        let bad = NatsAuth {
            creds_file: Some(garbage),
            ..NatsAuth::default()
        };
        assert!(bad.options().await.is_err());
    }
}
