//! Arguments that decide who may reach a server (`psao serve`, `psao edge`) and how a viewer
//! proves it may: the access token (flag, file or environment), allowed web origins, the
//! per-source connection cap and TLS. See docs/SECURITY.md.

use std::path::PathBuf;

use anyhow::{bail, Result};
use psao_net::admission::DEFAULT_MAX_PER_SOURCE;

/// The access token, from `--token-file`, `--token` or `PSAO_TOKEN`.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct TokenArgs {
    /// Access token. A flag is visible to every local user (`ps`): prefer --token-file or
    /// the environment variable.
    #[arg(long, env = "PSAO_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// File whose first line is the access token (wins over --token and PSAO_TOKEN).
    #[arg(long, value_name = "FILE")]
    pub token_file: Option<PathBuf>,
}

/// Longest token file read: a token is a line, not a document.
const MAX_TOKEN_FILE: u64 = 4096;

impl TokenArgs {
    /// The token, if one was given.
    pub fn token(&self) -> Result<Option<String>> {
        let Some(path) = &self.token_file else {
            return match self.token.as_deref() {
                Some("") => bail!("the access token (--token or PSAO_TOKEN) is empty"),
                t => Ok(t.map(str::to_owned)),
            };
        };
        // The error names the file and what is wrong with it.
        Ok(Some(psao_net::secret::first_line(path, MAX_TOKEN_FILE)?))
    }
}

/// Who may reach a server, and over what.
#[derive(clap::Args, Debug, Clone)]
pub struct ExposureArgs {
    #[command(flatten)]
    pub token: TokenArgs,
    /// Also answer web pages of this origin (`https://HOST[:PORT]`; repeatable): their
    /// WebSocket sessions and cross-origin `/health`, and their host name in `Host`. The
    /// server's own origin and loopback pages are always allowed.
    #[arg(long = "allow-origin", value_name = "ORIGIN")]
    pub allow_origins: Vec<String>,
    /// Most connections open at once from one source address (IPv6: one /64).
    #[arg(long, default_value_t = DEFAULT_MAX_PER_SOURCE)]
    pub max_per_source: usize,
    /// Serve over TLS with this PEM certificate chain (https, wss; needs --tls-key).
    #[arg(long, requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// The PEM private key of --tls-cert.
    #[arg(long, requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
}

impl ExposureArgs {
    /// The TLS acceptor, when a certificate was given.
    pub fn tls(&self) -> Result<Option<psao_net::tls::TlsAcceptor>> {
        Ok(match (&self.tls_cert, &self.tls_key) {
            (Some(cert), Some(key)) => Some(psao_net::tls::acceptor(cert, key)?),
            _ => None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_token_file_wins_and_bad_files_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("token");
        std::fs::write(&file, "s3cret\nsecond line\n").unwrap();
        let args = TokenArgs {
            token: Some("flag".into()),
            token_file: Some(file.clone()),
        };
        assert_eq!(args.token().unwrap().as_deref(), Some("s3cret"));
        std::fs::write(&file, "\n").unwrap();
        assert!(args.token().unwrap_err().to_string().contains("empty"));
        std::fs::write(&file, vec![b'x'; 5000]).unwrap();
        assert!(args.token().is_err());
        let dir_as_file = TokenArgs {
            token: None,
            token_file: Some(dir.path().to_path_buf()),
        };
        assert!(dir_as_file.token().is_err());
        let empty_flag = TokenArgs {
            token: Some(String::new()),
            token_file: None,
        };
        assert!(empty_flag.token().is_err());
    }
}
