//! SROS2 (DDS Security) from the standard ROS 2 environment, as rcl reads it:
//!
//! - `ROS_SECURITY_ENABLE`: security is on when it is exactly `true`;
//! - `ROS_SECURITY_STRATEGY`: `Enforce` refuses to start without valid
//!   security files; anything else (rcl's `Permissive`) starts unsecured,
//!   with a warning, when they are missing or bad;
//! - `ROS_SECURITY_KEYSTORE`: the keystore (e.g. made by `ros2 security
//!   create_keystore` or tools/sros2_keystore.sh);
//! - `ROS_SECURITY_ENCLAVE_OVERRIDE`: the enclave, else `--ros-args
//!   --enclave`, else `/`.
//!
//! The enclave's directory `KEYSTORE/enclaves/ENCLAVE` holds the files rcl
//! names: identity_ca.cert.pem, cert.pem, key.pem, permissions_ca.cert.pem,
//! governance.p7s and permissions.p7s. They are given to RustDDS's built-in
//! security plugins (authentication PKI-DH, access control Permissions,
//! cryptography AES-GCM-GMAC), which authenticate every remote participant
//! and check its permissions against the governance. Payload protection
//! (`data_protection_kind` ENCRYPT or SIGN) does not work between RustDDS
//! 0.15.1 participants, and RustDDS rejects Cyclone DDS 0.10.2's handshake
//! (docs/ros.md). Security needs the
//! cargo feature `security`; without it `ROS_SECURITY_ENABLE=true` with
//! `Enforce` refuses to start.

use anyhow::{anyhow, bail, Result};
use ros2_client::{Context, ContextOptions};
use std::path::{Path, PathBuf};

/// The files rcl looks for in an enclave's directory.
pub const ENCLAVE_FILES: [&str; 6] = [
    "identity_ca.cert.pem",
    "cert.pem",
    "key.pem",
    "permissions_ca.cert.pem",
    "governance.p7s",
    "permissions.p7s",
];

/// Whether this build has DDS Security (the cargo feature `security`).
pub const AVAILABLE: bool = cfg!(feature = "security");

/// What the environment asks for.
#[derive(Debug, Clone, PartialEq)]
pub enum Plan {
    /// Security off (`ROS_SECURITY_ENABLE` is not `true`).
    Off,
    /// Secured with the enclave directory's files.
    Secured { enclave: String, dir: PathBuf },
    /// Permissive strategy without usable files: unsecured, with this warning.
    Fallback(String),
}

/// The plan from the environment variables read through `var` and the
/// `--enclave` argument. An error (Enforce without usable files) names the
/// variable or the file.
pub fn plan(var: impl Fn(&str) -> Option<String>, enclave_arg: Option<&str>) -> Result<Plan> {
    let set = |k: &str| var(k).filter(|v| !v.is_empty());
    if set("ROS_SECURITY_ENABLE").as_deref() != Some("true") {
        return Ok(Plan::Off);
    }
    let enforce = set("ROS_SECURITY_STRATEGY").as_deref() == Some("Enforce");
    let enclave = set("ROS_SECURITY_ENCLAVE_OVERRIDE")
        .or_else(|| enclave_arg.map(str::to_string))
        .unwrap_or_else(|| "/".to_string());
    let found = enclave_dir(set("ROS_SECURITY_KEYSTORE"), &enclave).and_then(|dir| {
        if !AVAILABLE {
            bail!(
                "ROS_SECURITY_ENABLE=true: this garment_sim was built without DDS Security \
                 (cargo feature `security`)"
            );
        }
        check_files(&dir)?;
        Ok(dir)
    });
    match found {
        Ok(dir) => Ok(Plan::Secured { enclave, dir }),
        Err(e) if enforce => {
            Err(e.context("ROS_SECURITY_STRATEGY=Enforce: refusing to start without DDS Security"))
        }
        Err(e) => Ok(Plan::Fallback(format!(
            "{e:#}; ROS_SECURITY_STRATEGY is not Enforce: starting WITHOUT DDS Security"
        ))),
    }
}

/// `KEYSTORE/enclaves/ENCLAVE` (enclave `/` being `KEYSTORE/enclaves`).
fn enclave_dir(keystore: Option<String>, enclave: &str) -> Result<PathBuf> {
    let keystore = keystore
        .ok_or_else(|| anyhow!("ROS_SECURITY_ENABLE=true but ROS_SECURITY_KEYSTORE is not set"))?;
    if !enclave.starts_with('/') || enclave.split('/').any(|p| p == "..") {
        bail!("enclave {enclave:?}: must be an absolute name like /garment_sim, without `..`");
    }
    let dir = Path::new(&keystore)
        .join("enclaves")
        .join(enclave.trim_start_matches('/'));
    if !dir.is_dir() {
        bail!(
            "enclave {enclave}: no directory {} (ROS_SECURITY_KEYSTORE = {keystore})",
            dir.display()
        );
    }
    Ok(dir)
}

/// Each file of [`ENCLAVE_FILES`] is there and looks like what it must be
/// (PEM certificate, PEM private key, S/MIME signed document); RustDDS
/// checks the signatures and the chain when the participant starts.
pub fn check_files(dir: &Path) -> Result<()> {
    for name in ENCLAVE_FILES {
        let path = dir.join(name);
        let bytes = std::fs::read(&path).map_err(|e| anyhow!("{}: {e}", path.display()))?;
        let text = String::from_utf8_lossy(&bytes);
        let (ok, what) = match name {
            "key.pem" => (text.contains("PRIVATE KEY-----"), "a PEM private key"),
            n if n.ends_with(".pem") => (
                text.contains("-----BEGIN CERTIFICATE-----"),
                "a PEM certificate",
            ),
            _ => (
                text.contains("application/pkcs7-signature")
                    || text.contains("application/x-pkcs7-signature"),
                "an S/MIME signed document (openssl smime -sign)",
            ),
        };
        if !ok {
            bail!("{}: not {what}", path.display());
        }
    }
    Ok(())
}

/// `GARMENT_SIM_DDS_LOG=LEVEL` (error, warn, info, debug, trace): RustDDS's
/// own log lines (e.g. why a security handshake failed) on stderr.
struct DdsLog;

impl log::Log for DdsLog {
    fn enabled(&self, m: &log::Metadata) -> bool {
        m.level() <= log::max_level()
    }
    fn log(&self, r: &log::Record) {
        if self.enabled(r.metadata()) {
            eprintln!("[dds {} {}] {}", r.level(), r.target(), r.args());
        }
    }
    fn flush(&self) {}
}

/// Turns RustDDS's log lines on as `GARMENT_SIM_DDS_LOG` asks (the node
/// does at start; a client of its own, e.g. a test's, may too).
pub fn dds_log() {
    static LOGGER: DdsLog = DdsLog;
    let Ok(level) = std::env::var("GARMENT_SIM_DDS_LOG") else {
        return;
    };
    if let Ok(l) = level.parse::<log::LevelFilter>() {
        if log::set_logger(&LOGGER).is_ok() {
            log::set_max_level(l);
        }
    }
}

/// The ROS 2 context on `domain`, secured as the environment asks. Returns
/// the lines to log once the node's log is up (what security is in force,
/// or the Permissive fallback's warning) with their level (`true`: warning).
pub fn context(domain: u16, enclave_arg: Option<&str>) -> Result<(Context, Vec<(bool, String)>)> {
    dds_log();
    let plan = plan(|k| std::env::var(k).ok(), enclave_arg)?;
    let enforce = std::env::var("ROS_SECURITY_STRATEGY").as_deref() == Ok("Enforce");
    let plain = |notes| -> Result<(Context, Vec<(bool, String)>)> {
        let c = Context::with_options(ContextOptions::new().domain_id(domain))
            .map_err(|e| anyhow!("cannot start DDS: {e:?}"))?;
        Ok((c, notes))
    };
    match plan {
        Plan::Off => plain(vec![]),
        Plan::Fallback(w) => plain(vec![(true, w)]),
        Plan::Secured { enclave, dir } => match secured(domain, &dir) {
            Ok(c) => Ok((
                c,
                vec![(
                    false,
                    format!(
                        "DDS Security on: enclave {enclave} ({}), strategy {}",
                        dir.display(),
                        if enforce { "Enforce" } else { "Permissive" }
                    ),
                )],
            )),
            Err(e) if enforce => Err(
                e.context("ROS_SECURITY_STRATEGY=Enforce: refusing to start without DDS Security")
            ),
            Err(e) => plain(vec![(
                true,
                format!(
                    "{e:#}; ROS_SECURITY_STRATEGY is not Enforce: starting WITHOUT DDS Security"
                ),
            )]),
        },
    }
}

#[cfg(feature = "security")]
fn secured(domain: u16, dir: &Path) -> Result<Context> {
    // the private key is not encrypted (as sros2 writes it): no password
    Context::with_options(
        ContextOptions::new()
            .domain_id(domain)
            .enable_security(dir, String::new()),
    )
    .map_err(|e| {
        anyhow!(
            "cannot start DDS Security with the files in {} ({}): {e:?}",
            dir.display(),
            ENCLAVE_FILES.join(", ")
        )
    })
}

#[cfg(not(feature = "security"))]
fn secured(_domain: u16, _dir: &Path) -> Result<Context> {
    unreachable!("plan() refuses security in a build without the feature")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn run(vars: &[(&str, &str)], arg: Option<&str>) -> Result<Plan> {
        let m: HashMap<String, String> = vars
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        plan(|k| m.get(k).cloned(), arg)
    }

    fn keystore(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("garment_sim_sec_{name}_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        let e = d.join("enclaves/garment_sim");
        std::fs::create_dir_all(&e).unwrap();
        for f in ENCLAVE_FILES {
            let body = match f {
                "key.pem" => "-----BEGIN PRIVATE KEY-----\n",
                f if f.ends_with(".pem") => "-----BEGIN CERTIFICATE-----\n",
                _ => "Content-Type: multipart/signed; protocol=\"application/x-pkcs7-signature\"\n",
            };
            std::fs::write(e.join(f), body).unwrap();
        }
        d
    }

    #[test]
    fn off_unless_enable_is_exactly_true() {
        assert_eq!(run(&[], None).unwrap(), Plan::Off);
        assert_eq!(
            run(&[("ROS_SECURITY_ENABLE", "1")], None).unwrap(),
            Plan::Off
        );
        assert_eq!(
            run(&[("ROS_SECURITY_ENABLE", "TRUE")], None).unwrap(),
            Plan::Off
        );
    }

    #[test]
    fn enforce_names_what_is_missing_permissive_falls_back() {
        let e = run(
            &[
                ("ROS_SECURITY_ENABLE", "true"),
                ("ROS_SECURITY_STRATEGY", "Enforce"),
            ],
            None,
        )
        .unwrap_err();
        let m = format!("{e:#}");
        assert!(
            m.contains("ROS_SECURITY_KEYSTORE") && m.contains("Enforce"),
            "{m}"
        );
        let w = run(&[("ROS_SECURITY_ENABLE", "true")], None).unwrap();
        assert!(
            matches!(&w, Plan::Fallback(m) if m.contains("ROS_SECURITY_KEYSTORE") && m.contains("WITHOUT")),
            "{w:?}"
        );
        if !AVAILABLE {
            return;
        }
        let ks = keystore("files");
        let k = ks.to_str().unwrap();
        let env = [
            ("ROS_SECURITY_ENABLE", "true"),
            ("ROS_SECURITY_STRATEGY", "Enforce"),
            ("ROS_SECURITY_KEYSTORE", k),
            ("ROS_SECURITY_ENCLAVE_OVERRIDE", "/garment_sim"),
        ];
        // the override wins over --enclave
        assert_eq!(
            run(&env, Some("/other")).unwrap(),
            Plan::Secured {
                enclave: "/garment_sim".into(),
                dir: ks.join("enclaves/garment_sim")
            }
        );
        // --enclave when there is no override; a missing enclave named
        let m = format!("{:#}", run(&env[..3], Some("/other")).unwrap_err());
        assert!(
            m.contains("enclave /other") && m.contains("enclaves/other"),
            "{m}"
        );
        // each file missing, then not what it must be, is named
        for f in ENCLAVE_FILES {
            let p = ks.join("enclaves/garment_sim").join(f);
            let keep = std::fs::read(&p).unwrap();
            std::fs::remove_file(&p).unwrap();
            let m = format!("{:#}", run(&env, None).unwrap_err());
            assert!(m.contains(&p.display().to_string()), "{m}");
            std::fs::write(&p, "junk").unwrap();
            let m = format!("{:#}", run(&env, None).unwrap_err());
            assert!(
                m.contains(&p.display().to_string()) && m.contains("not "),
                "{m}"
            );
            std::fs::write(&p, keep).unwrap();
        }
        let _ = std::fs::remove_dir_all(&ks);
    }

    #[test]
    fn enclave_names_must_be_absolute() {
        let env = [
            ("ROS_SECURITY_ENABLE", "true"),
            ("ROS_SECURITY_STRATEGY", "Enforce"),
            ("ROS_SECURITY_KEYSTORE", "/nonexistent"),
            ("ROS_SECURITY_ENCLAVE_OVERRIDE", "/../etc"),
        ];
        let m = format!("{:#}", run(&env, None).unwrap_err());
        assert!(m.contains("\"/../etc\""), "{m}");
    }
}
