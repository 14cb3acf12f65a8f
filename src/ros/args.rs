//! ROS 2 command-line arguments (`--ros-args ... [--]`), as rcl reads them:
//! `-p name:=value` / `--param`, `--params-file FILE`, `-r from:=to` /
//! `--remap` (with `__ns` and `__node`), `--log-level LEVEL`. Values are YAML
//! scalars, as in ROS 2 (`true`, `3`, `0.5`, `text`).

use anyhow::{anyhow, bail, Context, Result};
use std::path::{Path, PathBuf};

/// A parameter value as ROS 2 types it.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    Bool(bool),
    Int(i64),
    Double(f64),
    Str(String),
}

impl Value {
    /// From a YAML scalar (`-p` values and params files).
    pub fn from_yaml(v: &serde_yaml::Value) -> Result<Value> {
        Ok(match v {
            serde_yaml::Value::Bool(b) => Value::Bool(*b),
            serde_yaml::Value::Number(n) => {
                if let Some(i) = n.as_i64() {
                    Value::Int(i)
                } else {
                    Value::Double(
                        n.as_f64()
                            .ok_or_else(|| anyhow!("number {n} out of range"))?,
                    )
                }
            }
            serde_yaml::Value::String(s) => Value::Str(s.clone()),
            serde_yaml::Value::Null => Value::Str(String::new()),
            other => bail!("unsupported parameter value {other:?} (scalars only)"),
        })
    }

    pub fn parse(text: &str) -> Result<Value> {
        let y: serde_yaml::Value =
            serde_yaml::from_str(text).unwrap_or(serde_yaml::Value::String(text.into()));
        Value::from_yaml(&y)
    }
}

/// What `--ros-args` said.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RosArgs {
    /// `-p` assignments in order (later ones win).
    pub params: Vec<(String, Value)>,
    pub params_files: Vec<PathBuf>,
    /// Topic and service remaps `from:=to` (without `__ns` / `__node`).
    pub remaps: Vec<(String, String)>,
    pub namespace: Option<String>,
    pub node_name: Option<String>,
    pub log_level: Option<String>,
    /// `-e/--enclave`: the SROS2 enclave (see [`super::security`]).
    pub enclave: Option<String>,
}

fn split_assign<'a>(flag: &str, s: &'a str) -> Result<(&'a str, &'a str)> {
    s.split_once(":=")
        .filter(|(a, _)| !a.is_empty())
        .ok_or_else(|| anyhow!("{flag} {s:?}: expected name:=value"))
}

/// Reads the arguments after the subcommand: everything outside
/// `--ros-args ... [--]` is returned untouched.
pub fn parse(args: &[String]) -> Result<(Vec<String>, RosArgs)> {
    let mut rest = Vec::new();
    let mut ra = RosArgs::default();
    let mut i = 0;
    let mut in_ros = false;
    while i < args.len() {
        let a = args[i].as_str();
        if !in_ros {
            if a == "--ros-args" {
                in_ros = true;
            } else {
                rest.push(a.to_string());
            }
            i += 1;
            continue;
        }
        let next = |i: usize| -> Result<&str> {
            args.get(i + 1)
                .map(|s| s.as_str())
                .ok_or_else(|| anyhow!("--ros-args: {a} needs a value"))
        };
        match a {
            "--" => in_ros = false,
            "--ros-args" => {}
            "-p" | "--param" => {
                let v = next(i)?;
                let (name, value) = split_assign(a, v)?;
                ra.params.push((name.to_string(), Value::parse(value)?));
                i += 1;
            }
            "--params-file" => {
                ra.params_files.push(PathBuf::from(next(i)?));
                i += 1;
            }
            "-r" | "--remap" => {
                let v = next(i)?;
                let (from, to) = split_assign(a, v)?;
                // `node_name:__ns:=...` targets one node; we are the only one.
                let from = from.rsplit_once(':').map(|(_, f)| f).unwrap_or(from);
                match from {
                    "__ns" => ra.namespace = Some(to.to_string()),
                    "__node" | "__name" => ra.node_name = Some(to.to_string()),
                    _ => ra.remaps.push((from.to_string(), to.to_string())),
                }
                i += 1;
            }
            "--log-level" => {
                ra.log_level = Some(next(i)?.to_string());
                i += 1;
            }
            "-e" | "--enclave" => {
                ra.enclave = Some(next(i)?.to_string());
                i += 1;
            }
            "--disable-rosout-logs"
            | "--disable-stdout-logs"
            | "--enable-rosout-logs"
            | "--enable-stdout-logs"
            | "--disable-external-lib-logs" => {}
            other => bail!(
                "--ros-args: unknown argument {other:?} (known: -p/--param name:=value, \
                 --params-file FILE, -r/--remap from:=to, --log-level LEVEL, --)"
            ),
        }
        i += 1;
    }
    Ok((rest, ra))
}

/// Reads a ROS 2 params file for node `fq_name` (e.g. `/garment_sim` or
/// `/ns/garment_sim`): sections keyed by the node's fully qualified name, its
/// base name, or the `/**` wildcard, each with a `ros__parameters` map; nested
/// maps give dotted names. Sections are applied wildcard first.
pub fn read_params_file(path: &Path, fq_name: &str) -> Result<Vec<(String, Value)>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read params file {}", path.display()))?;
    crate::io::check_yaml_shape(&text)
        .with_context(|| format!("params file {}", path.display()))?;
    let doc: serde_yaml::Value = serde_yaml::from_str(&text)
        .with_context(|| format!("params file {}: not valid YAML", path.display()))?;
    let map = doc.as_mapping().ok_or_else(|| {
        anyhow!(
            "params file {}: top level must be a map of node names",
            path.display()
        )
    })?;
    let base = fq_name.rsplit('/').next().unwrap_or(fq_name);
    let mut sections: Vec<(u8, &serde_yaml::Value, String)> = Vec::new();
    for (k, v) in map {
        let key = k.as_str().unwrap_or_default();
        let rank = if key == "/**" || key == "**" {
            0
        } else if key == fq_name || key == format!("/**/{base}") {
            2
        } else if key == base {
            1
        } else {
            continue;
        };
        sections.push((rank, v, key.to_string()));
    }
    sections.sort_by_key(|s| s.0);
    let mut out = Vec::new();
    for (_, v, key) in sections {
        let p = v.get("ros__parameters").ok_or_else(|| {
            anyhow!(
                "params file {}: section {key:?} has no ros__parameters",
                path.display()
            )
        })?;
        flatten(p, "", &mut out)
            .with_context(|| format!("params file {}, section {key:?}", path.display()))?;
    }
    Ok(out)
}

fn flatten(v: &serde_yaml::Value, prefix: &str, out: &mut Vec<(String, Value)>) -> Result<()> {
    let m = v
        .as_mapping()
        .ok_or_else(|| anyhow!("ros__parameters must be a map"))?;
    for (k, v) in m {
        let k = k
            .as_str()
            .ok_or_else(|| anyhow!("parameter name {k:?} is not a string"))?;
        let name = if prefix.is_empty() {
            k.to_string()
        } else {
            format!("{prefix}.{k}")
        };
        if v.is_mapping() {
            flatten(v, &name, out)?;
        } else {
            out.push((
                name.clone(),
                Value::from_yaml(v).with_context(|| format!("parameter {name:?}"))?,
            ));
        }
    }
    Ok(())
}

/// Fully qualified name of a topic or service, as rcl expands it:
/// `~/x` → `<ns>/<node>/x`, `x` → `<ns>/x`, `/x` stays.
pub fn expand(name: &str, namespace: &str, node: &str) -> String {
    let ns = namespace.trim_end_matches('/');
    if let Some(rest) = name.strip_prefix("~/") {
        format!("{ns}/{node}/{rest}")
    } else if name == "~" {
        format!("{ns}/{node}")
    } else if name.starts_with('/') {
        name.to_string()
    } else {
        format!("{ns}/{name}")
    }
}

/// Applies remap rules to a name (matched on its expanded form; a rule's
/// target is expanded too). The first matching rule wins, as in rcl.
pub fn remap(name: &str, namespace: &str, node: &str, rules: &[(String, String)]) -> String {
    let full = expand(name, namespace, node);
    for (from, to) in rules {
        if expand(from, namespace, node) == full {
            return expand(to, namespace, node);
        }
    }
    full
}

/// Checks a namespace given with `__ns` (absolute, ROS 2 name tokens).
pub fn check_namespace(ns: &str) -> Result<String> {
    let ns = if ns.starts_with('/') {
        ns.to_string()
    } else {
        format!("/{ns}")
    };
    let trimmed = ns.trim_end_matches('/');
    for tok in trimmed.split('/').skip(1) {
        if tok.is_empty()
            || !tok.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
            || tok.starts_with(|c: char| c.is_ascii_digit())
        {
            bail!("namespace {ns:?}: each part must be letters, digits and _, not starting with a digit");
        }
    }
    Ok(if trimmed.is_empty() {
        "/".into()
    } else {
        trimmed.into()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(v: &[&str]) -> Vec<String> {
        v.iter().map(|x| x.to_string()).collect()
    }

    #[test]
    fn parses_ros_args() {
        let (rest, ra) = parse(&s(&[
            "--foo",
            "--ros-args",
            "-p",
            "publish_rate:=10.0",
            "-p",
            "paused:=true",
            "--param",
            "scene:=config/x.yaml",
            "-r",
            "__ns:=/robot1",
            "-r",
            "garment_sim:__node:=cloth",
            "-r",
            "cloth/points:=/points",
            "--params-file",
            "p.yaml",
            "--",
            "tail",
        ]))
        .unwrap();
        assert_eq!(rest, s(&["--foo", "tail"]));
        assert_eq!(
            ra.params,
            vec![
                ("publish_rate".into(), Value::Double(10.0)),
                ("paused".into(), Value::Bool(true)),
                ("scene".into(), Value::Str("config/x.yaml".into())),
            ]
        );
        assert_eq!(ra.namespace.as_deref(), Some("/robot1"));
        assert_eq!(ra.node_name.as_deref(), Some("cloth"));
        assert_eq!(ra.remaps, vec![("cloth/points".into(), "/points".into())]);
        assert_eq!(ra.params_files, vec![PathBuf::from("p.yaml")]);
        assert!(parse(&s(&["--ros-args", "-p", "novalue"])).is_err());
        assert!(parse(&s(&["--ros-args", "-p"])).is_err());
        assert!(parse(&s(&["--ros-args", "--bogus"]))
            .unwrap_err()
            .to_string()
            .contains("--bogus"));
    }

    #[test]
    fn names_expand_and_remap() {
        assert_eq!(expand("~/reset", "/", "garment_sim"), "/garment_sim/reset");
        assert_eq!(expand("cloth/points", "/r1", "g"), "/r1/cloth/points");
        assert_eq!(expand("/clock", "/r1", "g"), "/clock");
        let rules = vec![("cloth/points".to_string(), "pts".to_string())];
        assert_eq!(remap("cloth/points", "/r1", "g", &rules), "/r1/pts");
        assert_eq!(remap("cloth/mesh", "/r1", "g", &rules), "/r1/cloth/mesh");
        assert_eq!(check_namespace("r1/").unwrap(), "/r1");
        assert!(check_namespace("/1bad").is_err());
    }

    #[test]
    fn params_file_sections() {
        let dir = std::env::temp_dir().join(format!("gs_params_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("p.yaml");
        std::fs::write(
            &p,
            "/**:\n  ros__parameters:\n    frame_id: map\n    publish_rate: 5\n\
             /r1/garment_sim:\n  ros__parameters:\n    publish_rate: 12.5\n    solver:\n      kind: pcg\n\
             other_node:\n  ros__parameters:\n    publish_rate: 99\n",
        )
        .unwrap();
        let v = read_params_file(&p, "/r1/garment_sim").unwrap();
        assert_eq!(
            v,
            vec![
                ("frame_id".into(), Value::Str("map".into())),
                ("publish_rate".into(), Value::Int(5)),
                ("publish_rate".into(), Value::Double(12.5)),
                ("solver.kind".into(), Value::Str("pcg".into())),
            ]
        );
        std::fs::write(&p, "garment_sim:\n  params: {}\n").unwrap();
        assert!(
            format!("{:#}", read_params_file(&p, "/garment_sim").unwrap_err())
                .contains("ros__parameters")
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
