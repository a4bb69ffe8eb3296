//! The operating-system side of the daemon: `scripts/check-units` accepts the shipped unit,
//! sysusers.d, tmpfiles.d and udev files and rejects broken copies of them, and
//! `scripts/package` builds a Debian package of the test build's binary with every file in
//! place, inspected with `dpkg-deb`. Needs systemd, udev and dpkg-dev (scripts/setup.sh); as
//! root (CI), the udev rules also go through `udevadm test` in a private mount namespace.

use crate::util::repo_root;
use std::collections::BTreeMap;
use std::fs;
use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::process::{Command, Output};

/// The files `scripts/check-units` reads, relative to the repository's root.
const UNIT_FILES: [&str; 5] = [
    "scripts/check-units",
    "systemd/mousepose.service",
    "systemd/mousepose.sysusers",
    "systemd/mousepose.tmpfiles",
    "udev/60-mousepose.rules",
];

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn both(o: &Output) -> String {
    format!("{}{}", text(&o.stdout), text(&o.stderr))
}

/// Whether the tests run as root (CI does): then `udevadm test` must have run too.
fn is_root() -> bool {
    let status = fs::read_to_string("/proc/self/status").expect("reads /proc/self/status");
    // Uid: real, effective, saved, filesystem.
    status
        .lines()
        .find_map(|l| l.strip_prefix("Uid:"))
        .and_then(|ids| ids.split_whitespace().nth(1))
        == Some("0")
}

/// Runs the `scripts/check-units` found under `root`.
fn check_units(root: &Path) -> Output {
    Command::new(root.join("scripts/check-units"))
        .output()
        .expect("runs scripts/check-units")
}

/// A copy of the files `check-units` reads, with `file` changed by `edit`.
fn broken_copy(file: &str, edit: impl FnOnce(&str) -> String) -> tempfile::TempDir {
    let tmp = tempfile::tempdir().expect("tmp");
    for f in UNIT_FILES {
        let to = tmp.path().join(f);
        fs::create_dir_all(to.parent().expect("a parent")).expect("mkdir");
        fs::copy(repo_root().join(f), &to).expect("copies"); // with its mode: the script stays executable
    }
    let path = tmp.path().join(file);
    let before = fs::read_to_string(&path).expect("reads");
    let after = edit(&before);
    assert_ne!(before, after, "the edit changed nothing in {file}");
    fs::write(&path, after).expect("writes");
    tmp
}

/// Runs `check-units` on a broken copy and returns its stderr, which must name the problem.
fn rejected(file: &str, edit: impl FnOnce(&str) -> String) -> String {
    let tmp = broken_copy(file, edit);
    let o = check_units(tmp.path());
    assert!(
        !o.status.success(),
        "check-units accepted a broken {file}:\n{}",
        both(&o)
    );
    text(&o.stderr)
}

#[test]
fn check_units_accepts_the_shipped_files() {
    let o = check_units(&repo_root());
    let out = both(&o);
    assert!(o.status.success(), "{out}");
    for line in [
        "systemd/mousepose.service: systemd-analyze verify is clean",
        "systemd/mousepose.service: systemd-analyze security rates its exposure",
        "systemd/mousepose.sysusers: creates mousepose",
        "systemd/mousepose.tmpfiles: creates /var/lib/mousepose and its sessions directory, mode 0750",
        "udev/60-mousepose.rules: the lint is clean",
    ] {
        assert!(out.contains(line), "no '{line}' in:\n{out}");
    }
    if is_root() {
        assert!(
            out.contains("udev/60-mousepose.rules: udevadm test read it without a complaint"),
            "as root, the rules must go through udevadm test (is unshare allowed here?):\n{out}"
        );
    }
}

#[test]
fn check_units_rejects_a_setting_this_systemd_does_not_know() {
    // RestartSteps= came with systemd 254; Debian 12 has 252 and would ignore it.
    let err = rejected("systemd/mousepose.service", |s| {
        s.replace("RestartSec=5s\n", "RestartSec=5s\nRestartSteps=5\n")
    });
    assert!(err.contains("Unknown key 'RestartSteps'"), "{err}");
    assert!(
        err.contains("systemd-analyze verify warns about systemd/mousepose.service"),
        "{err}"
    );
}

#[test]
fn check_units_rejects_a_user_outside_the_camera_groups() {
    let err = rejected("systemd/mousepose.sysusers", |s| s.replace("m mousepose plugdev\n", ""));
    assert!(
        err.contains("systemd/mousepose.sysusers does not put mousepose in the plugdev group"),
        "{err}"
    );
}

#[test]
fn check_units_rejects_rules_that_give_cameras_to_another_group() {
    let err = rejected("udev/60-mousepose.rules", |s| {
        s.replace("GROUP=\"mousepose\"", "GROUP=\"camera\"")
    });
    assert!(
        err.contains("gives devices to the group camera, which systemd/mousepose.sysusers does not create"),
        "{err}"
    );
}

#[test]
fn check_units_rejects_rules_with_a_missing_comma() {
    let err = rejected("udev/60-mousepose.rules", |s| {
        s.replacen("ATTR{idVendor}==\"2bc5\", ", "ATTR{idVendor}==\"2bc5\" ", 1)
    });
    assert!(err.contains("missing comma before"), "{err}");
}

#[test]
fn udevadm_test_catches_what_the_lint_cannot() {
    // The lint does not know OPTIONS' values; udev does.
    let tmp = broken_copy("udev/60-mousepose.rules", |s| {
        s.replacen(
            "TAG+=\"systemd\"\n",
            "TAG+=\"systemd\", OPTIONS+=\"no_such_option\"\n",
            1,
        )
    });
    let o = check_units(tmp.path());
    let out = both(&o);
    if is_root() {
        assert!(!o.status.success(), "{out}");
        assert!(out.contains("Invalid value for OPTIONS key"), "{out}");
        assert!(
            out.contains("udevadm test reports problems in udev/60-mousepose.rules"),
            "{out}"
        );
    } else {
        // Without root only the lint runs, and it says so.
        assert!(o.status.success(), "{out}");
        assert!(out.contains("udevadm test skipped (not root)"), "{out}");
    }
}

/// Runs `dpkg-deb` with `args` and returns its stdout.
fn dpkg_deb(args: &[&str]) -> String {
    let o = Command::new("dpkg-deb").args(args).output().expect("runs dpkg-deb");
    assert!(o.status.success(), "dpkg-deb {args:?}: {}", text(&o.stderr));
    text(&o.stdout)
}

/// The `systemctl` subcommands a maintainer script runs (messages it prints left out).
fn systemctl_verbs(script: &str) -> Vec<String> {
    script
        .lines()
        .map(str::trim_start)
        .filter(|l| !l.starts_with('#') && !l.starts_with("echo") && !l.starts_with('"'))
        .map(|l| l.replace("command -v systemctl", ""))
        .flat_map(|l| {
            l.split("systemctl ")
                .skip(1)
                .map(|rest| {
                    let verb = rest.split_whitespace().find(|w| !w.starts_with('-')).unwrap_or("");
                    verb.to_owned()
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

#[test]
fn package_holds_the_daemon_and_its_system_files() {
    let tmp = tempfile::tempdir().expect("tmp");
    let out_dir = tmp.path().join("out");
    let o = Command::new(repo_root().join("scripts/package"))
        .arg("--binary")
        .arg(env!("CARGO_BIN_EXE_mousepose"))
        .arg("--out")
        .arg(&out_dir)
        .output()
        .expect("runs scripts/package");
    assert!(o.status.success(), "{}", both(&o));

    let arch = Command::new("dpkg")
        .arg("--print-architecture")
        .output()
        .expect("runs dpkg");
    let arch = text(&arch.stdout).trim().to_owned();
    // Debian sorts 1.2.0~rc.1 before 1.2.0, as semver does 1.2.0-rc.1.
    let version = env!("CARGO_PKG_VERSION").replacen('-', "~", 1);
    let deb_path = out_dir.join(format!("mousepose_{version}_{arch}.deb"));
    assert!(deb_path.is_file(), "no {}: {}", deb_path.display(), both(&o));
    let deb = deb_path.to_str().expect("a UTF-8 path");
    assert_eq!(text(&o.stdout).trim(), deb, "the script prints the package's path");

    // The control fields.
    let field = |name: &str| dpkg_deb(&["--field", deb, name]).trim().to_owned();
    assert_eq!(field("Package"), "mousepose");
    assert_eq!(field("Version"), version);
    assert_eq!(field("Architecture"), arch);
    assert!(!field("Maintainer").is_empty());
    assert!(!field("Description").is_empty());
    let depends = field("Depends");
    let names: Vec<&str> = depends
        .split([',', '|'])
        .filter_map(|d| d.split_whitespace().next())
        .collect();
    for prefix in [
        "libopenni2-0",
        "libaravis-0.8",
        "libopencv-core",
        "libopencv-imgproc",
        "libc6",
        "systemd",
        // `export moseq`, `export video` and MoSeq replays run the ffmpeg program.
        "ffmpeg",
    ] {
        assert!(
            names.iter().any(|n| n.starts_with(prefix)),
            "no {prefix}* in Depends: {depends}"
        );
    }

    // Every file in place, owned by root, with sane modes.
    let listing = dpkg_deb(&["--contents", deb]);
    let mut entries = BTreeMap::new();
    for line in listing.lines() {
        // drwxr-xr-x root/root         0 2025-01-01 00:00 ./etc/
        let cols: Vec<&str> = line.split_whitespace().collect();
        assert!(cols.len() >= 6, "unexpected line in the listing: {line}");
        let path = cols[5].trim_start_matches('.').trim_end_matches('/').to_owned();
        entries.insert(path, (cols[0].to_owned(), cols[1].to_owned()));
    }
    let expected = [
        ("/usr/bin/mousepose", "-rwxr-xr-x"),
        ("/usr/share/mousepose/models/body.forest", "-rw-r--r--"),
        ("/usr/share/mousepose/models/paws.xml", "-rw-r--r--"),
        ("/usr/share/mousepose/models/orientation.json", "-rw-r--r--"),
        ("/lib/systemd/system/mousepose.service", "-rw-r--r--"),
        ("/usr/lib/sysusers.d/mousepose.conf", "-rw-r--r--"),
        ("/usr/lib/tmpfiles.d/mousepose.conf", "-rw-r--r--"),
        ("/lib/udev/rules.d/60-mousepose.rules", "-rw-r--r--"),
        ("/etc/mousepose/rig.toml", "-rw-r--r--"),
        ("/usr/share/mousepose/nwb-env", "-rwxr-xr-x"),
        ("/usr/share/doc/mousepose/README.md", "-rw-r--r--"),
        ("/usr/share/doc/mousepose/copyright", "-rw-r--r--"),
    ];
    for (path, mode) in expected {
        let Some((got, _)) = entries.get(path) else {
            panic!("{path} is not in the package:\n{listing}");
        };
        assert_eq!(got, mode, "{path}");
    }
    for (path, (mode, owner)) in &entries {
        assert_eq!(owner, "root/root", "{path}");
        if mode.starts_with('d') {
            assert_eq!(mode, "drwxr-xr-x", "{path}");
        } else {
            assert!(mode == "-rw-r--r--" || mode == "-rwxr-xr-x", "{path}: {mode}");
            assert!(
                ["/usr/", "/lib/", "/etc/mousepose/"]
                    .iter()
                    .any(|p| path.starts_with(p)),
                "{path} is outside the package's places"
            );
        }
    }

    // The files are the repository's own.
    let root = tmp.path().join("root");
    dpkg_deb(&["-x", deb, root.to_str().expect("a UTF-8 path")]);
    for (installed, source) in [
        ("lib/systemd/system/mousepose.service", "systemd/mousepose.service"),
        ("usr/lib/sysusers.d/mousepose.conf", "systemd/mousepose.sysusers"),
        ("usr/lib/tmpfiles.d/mousepose.conf", "systemd/mousepose.tmpfiles"),
        ("lib/udev/rules.d/60-mousepose.rules", "udev/60-mousepose.rules"),
        ("etc/mousepose/rig.toml", "docs/rig.example.toml"),
        ("usr/share/mousepose/models/body.forest", "fixtures/models/body.forest"),
        ("usr/share/mousepose/models/paws.xml", "fixtures/models/paws.xml"),
        (
            "usr/share/mousepose/models/orientation.json",
            "fixtures/models/orientation.json",
        ),
        ("usr/share/doc/mousepose/README.md", "README.md"),
        ("usr/share/mousepose/nwb-env", "scripts/nwb-env"),
    ] {
        let same = fs::read(root.join(installed)).expect("reads the packaged file")
            == fs::read(repo_root().join(source)).expect("reads the source");
        assert!(same, "/{installed} differs from {source}");
    }
    // The unit starts the packaged binary with the packaged config.
    let unit = fs::read_to_string(root.join("lib/systemd/system/mousepose.service")).expect("reads the unit");
    assert!(unit.contains("\nExecStart=/usr/bin/mousepose run --config /etc/mousepose/rig.toml\n"));
    let packaged = root.join("usr/bin/mousepose");
    let help = Command::new(&packaged)
        .arg("--help")
        .output()
        .expect("runs the packaged binary");
    assert!(help.status.success(), "{}", both(&help));
    let size = |p: &Path| fs::metadata(p).expect("stat").len();
    assert!(size(&packaged) <= size(Path::new(env!("CARGO_BIN_EXE_mousepose"))));

    // Control files: the conffile, checksums that match, maintainer scripts that parse.
    let control = tmp.path().join("control");
    dpkg_deb(&["-e", deb, control.to_str().expect("a UTF-8 path")]);
    assert_eq!(
        fs::read_to_string(control.join("conffiles")).expect("reads conffiles"),
        "/etc/mousepose/rig.toml\n"
    );
    let sums = Command::new("md5sum")
        .args(["--check", "--quiet"])
        .arg(control.join("md5sums"))
        .current_dir(&root)
        .output()
        .expect("runs md5sum");
    assert!(sums.status.success(), "{}", both(&sums));
    let mut scripts = BTreeMap::new();
    for name in ["postinst", "prerm", "postrm"] {
        let path = control.join(name);
        let mode = fs::metadata(&path).expect("stat").permissions().mode() & 0o7777;
        assert_eq!(mode, 0o755, "{name}");
        let syntax = Command::new("sh").arg("-n").arg(&path).output().expect("runs sh -n");
        assert!(syntax.status.success(), "{name}: {}", both(&syntax));
        scripts.insert(name, fs::read_to_string(&path).expect("reads"));
    }
    let postinst = &scripts["postinst"];
    for step in [
        "systemd-sysusers /usr/lib/sysusers.d/mousepose.conf",
        "systemd-tmpfiles --create /usr/lib/tmpfiles.d/mousepose.conf",
        "udevadm control --reload",
        "systemctl daemon-reload",
    ] {
        assert!(postinst.contains(step), "postinst does not run '{step}':\n{postinst}");
    }
    // The operator edits the config first: nothing enables, starts or restarts the daemon.
    for (name, allowed) in [
        ("postinst", &["daemon-reload", "is-active"][..]),
        ("prerm", &["stop", "disable"][..]),
        ("postrm", &["daemon-reload"][..]),
    ] {
        let verbs = systemctl_verbs(&scripts[name]);
        assert!(
            verbs.iter().all(|v| allowed.contains(&v.as_str())),
            "{name} runs systemctl {verbs:?}"
        );
    }
    assert!(systemctl_verbs(postinst).contains(&"daemon-reload".to_owned()));

    // The NWB environment: one command, named by the package's README and description.
    let readme = fs::read_to_string(root.join("usr/share/doc/mousepose/README.md")).expect("reads the README");
    assert!(readme.contains("sudo /usr/share/mousepose/nwb-env"));
    assert!(field("Description").contains("/usr/share/mousepose/nwb-env"));
    let syntax = Command::new("sh")
        .arg("-n")
        .arg(root.join("usr/share/mousepose/nwb-env"))
        .output()
        .expect("runs sh -n");
    assert!(syntax.status.success(), "{}", both(&syntax));

    // At install, the shipped config's Dummy depth device is named, and only while it is there.
    let said = run_postinst(
        &scripts["postinst"],
        &fs::read_to_string(root.join("etc/mousepose/rig.toml")).expect("reads"),
    );
    assert!(said.contains("Dummy") && said.contains("degraded"), "{said}");
    let edited = fs::read_to_string(repo_root().join("docs/rig.example.toml"))
        .expect("reads")
        .replace("uri = \"Dummy\"", "uri = \"1d27/0601@1/5\"");
    let said = run_postinst(&scripts["postinst"], &edited);
    assert!(!said.contains("Dummy"), "{said}");
}

/// Runs `postinst configure` (a first install) with `config` as its rig.toml, the system
/// programs it calls stubbed, and returns what it printed.
fn run_postinst(postinst: &str, config: &str) -> String {
    let tmp = tempfile::tempdir().expect("tmp");
    let rig = tmp.path().join("rig.toml");
    fs::write(&rig, config).expect("writes");
    let stubs = tmp.path().join("bin");
    fs::create_dir(&stubs).expect("mkdir");
    for program in ["systemd-sysusers", "systemd-tmpfiles", "udevadm", "systemctl"] {
        let path = stubs.join(program);
        fs::write(&path, "#!/bin/sh\nexit 0\n").expect("writes");
        fs::set_permissions(&path, fs::Permissions::from_mode(0o755)).expect("chmod");
    }
    let script = tmp.path().join("postinst");
    fs::write(
        &script,
        postinst.replace("/etc/mousepose/rig.toml", rig.to_str().expect("a UTF-8 path")),
    )
    .expect("writes");
    let path = format!("{}:{}", stubs.display(), std::env::var("PATH").unwrap_or_default());
    let o = Command::new("sh")
        .arg(&script)
        .arg("configure")
        .env("PATH", path)
        .output()
        .expect("runs postinst");
    assert!(o.status.success(), "{}", both(&o));
    both(&o)
}
