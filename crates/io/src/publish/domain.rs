//! Who may reach the tracker's shared-memory files: the iceoryx2 "domain" (its root folder, by
//! default `/tmp/iceoryx2`, and the `/dev/shm` files named with its prefix, by default `iox2_`)
//! checked before a node is made, and what this process made in it handed to the domain's group.
//!
//! In: iceoryx2's config as every iceoryx2 process finds it (root path, prefix; the defaults unless
//! a config file says otherwise), this process's user and groups (`/proc/self/status`). Out: a
//! [`Domain`] (its group, and the node config that names omnitrack's own node counter file), or one
//! line that names the file in the way, its owner, and what to do.
//!
//! Why: iceoryx2 0.10 fixes its permissions in code. Its node counter file in `/dev/shm` is mode
//! 0666, so any local user could damage it, which made every later node creation fail or hang
//! (issue 50); and every other file is owner-only, so a consumer in the tracker's group was
//! refused. Whoever started first owned the folder. Here:
//! - the root folder and its `nodes` and `services` folders must belong to this user or root, or
//!   be shared with a group of this process; made here when missing, as `2770` in this process's
//!   group (tools/deploy's tmpfiles.d makes them at boot, before any other user can);
//! - omnitrack's nodes count in a file of their own (suffix [`COUNTER_SUFFIX`]), made here as 0660
//!   before iceoryx2 ever sees it, never open to every user, so iceoryx2's 0666 file (still used by
//!   processes with iceoryx2's default config) cannot stop a tracker or a listener;
//! - a counter file that is truncated or holds a wrong version (it only counts, and node ids also
//!   hold the pid and the time) is rewritten in place by any process of the domain that can write
//!   it, instead of iceoryx2 waiting on it for ever;
//! - after making its node and ports, a process gives each file it owns in the domain to the
//!   domain's group with the owner's rights mirrored ([`Domain::share_with_group`]): a consumer in
//!   the tracker's group, and the tracker for a consumer's files, can then open them. Nothing is
//!   left open to other users.

use std::fs::{self, File, Metadata, OpenOptions};
use std::io::ErrorKind;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::{DirBuilderExt, FileExt, MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use iceoryx2::prelude::{Config, FileName, SemanticString};

mod identity;
use identity::{group, kind, user, who, Identity};

/// Where POSIX shared memory lives on Linux (iceoryx2's `shm_open` files).
pub const SHM_DIR: &str = "/dev/shm";

/// The suffix of omnitrack's own node counter file; iceoryx2's is `.global_mgmt`.
pub const COUNTER_SUFFIX: &str = ".omnitrack_mgmt";

/// The middle of iceoryx2 0.10.0's node counter file name: the SHA-1 of the counter's type name and
/// the package version (`iceoryx2::node::global_management_segment`). A test makes a node and
/// checks that iceoryx2 names its file so; tools/deploy/omnitrack.tmpfiles spells the same names.
const COUNTER_NAME: &str = "9204dd183d1c4d8e1ff592a30766ffa6765aa8b5_node.0_10_0";

/// The version word at the start of the counter file: iceoryx2 0.10.0 (`PackageVersion::to_u64`).
const COUNTER_VERSION: u64 = 10 << 16;

/// The counter file's size: the version word, the u32 counter and its padding.
const COUNTER_BYTES: usize = 16;

/// How long a file another process is still making (owner-write only) is waited for: iceoryx2's
/// own creation timeout.
const HALF_MADE_WAIT: Duration = Duration::from_secs(1);

/// What to do about a domain folder or file another user made first.
const REMEDY: &str = "tools/deploy/omnitrack.tmpfiles makes them at boot, before other users can";

/// The iceoryx2 domain this process's nodes use, checked, with the group its files are shared
/// with.
#[derive(Debug)]
pub struct Domain {
    root: PathBuf,
    prefix: String,
    group: u32,
    me: Identity,
    config: Config,
    /// iceoryx2's own node counter file, which default-config processes use.
    their_counter: PathBuf,
}

impl Domain {
    /// Checks the domain of iceoryx2's config (as every iceoryx2 process finds it) before a node
    /// is made: makes the root folder, its `nodes` and `services` folders and omnitrack's node
    /// counter file where they are missing (group-only), refuses them where another user holds
    /// them, and repairs a damaged counter file. `Err` is one line.
    pub fn prepare() -> Result<Self, String> {
        Self::prepare_with(Config::global_config().clone())
    }

    fn prepare_with(mut config: Config) -> Result<Self, String> {
        let their_suffix = config.global.node.global_mgmt_suffix.to_string();
        config.global.node.global_mgmt_suffix = FileName::new(COUNTER_SUFFIX.as_bytes())
            .map_err(|e| format!("the node counter suffix {COUNTER_SUFFIX}: {e:?}"))?;
        let me = Identity::of_this_process()?;
        let root = config.global.root_path().to_string();
        // "/tmp/iceoryx2/" is named without its slash in messages, as people write it.
        let root = PathBuf::from(match root.trim_end_matches('/') {
            "" => "/",
            r => r,
        });
        let prefix = config.global.prefix.to_string();
        let mut domain = Domain {
            root,
            prefix,
            group: me.gid,
            me,
            config,
            their_counter: PathBuf::new(),
        };
        domain.their_counter = domain.counter_file(&their_suffix);
        let root = domain.root.clone();
        domain.group = domain.folder(&root)?;
        for sub in [domain.config.global.node_dir(), domain.config.global.service_dir()] {
            domain.folder(Path::new(&sub.to_string()))?;
        }
        let ours = domain.counter_file(COUNTER_SUFFIX);
        domain.counter(&ours, true)?;
        // iceoryx2's own counter file serves processes with its default config (a Python
        // consumer): repaired where this process may write it, otherwise theirs to bear.
        if domain.their_counter != ours {
            let _ = domain.counter(&domain.their_counter, false);
        }
        Ok(domain)
    }

    /// The config for this process's nodes: iceoryx2's, with omnitrack's node counter file.
    pub fn node_config(&self) -> &Config {
        &self.config
    }

    /// `/dev/shm/<prefix><counter name><suffix>`.
    pub fn counter_file(&self, suffix: &str) -> PathBuf {
        Path::new(SHM_DIR).join(format!("{}{COUNTER_NAME}{suffix}", self.prefix))
    }

    /// A domain folder: checked, or made group-only. Returns its group.
    fn folder(&self, path: &Path) -> Result<u32, String> {
        for _ in 0..2 {
            match fs::symlink_metadata(path) {
                Ok(m) => return self.check_folder(path, &m),
                Err(e) if e.kind() == ErrorKind::NotFound => {
                    match fs::DirBuilder::new().mode(0o700).create(path) {
                        Ok(()) => {
                            // The group first, then its rights, so that no one else is let in
                            // between; setgid so what is made inside keeps the group.
                            let group = match path.parent().and_then(|p| fs::symlink_metadata(p).ok()) {
                                Some(parent) if path != self.root && self.me.member_of(parent.gid()) => parent.gid(),
                                _ => self.me.gid,
                            };
                            std::os::unix::fs::lchown(path, None, Some(group))
                                .and_then(|()| fs::set_permissions(path, fs::Permissions::from_mode(0o2770)))
                                .map_err(|e| format!("making {}: {e}", path.display()))?;
                            return Ok(group);
                        }
                        // Made by someone else meanwhile: check theirs.
                        Err(e) if e.kind() == ErrorKind::AlreadyExists => continue,
                        Err(e) => {
                            return Err(format!(
                                "cannot make iceoryx2's folder {}: {e}{}",
                                path.display(),
                                self.parent_hint(path)
                            ))
                        }
                    }
                }
                Err(e) => return Err(format!("cannot look at {}: {e}", path.display())),
            }
        }
        Err(format!(
            "{} keeps changing: another process makes and removes it",
            path.display()
        ))
    }

    fn parent_hint(&self, path: &Path) -> String {
        match path.parent().and_then(|p| fs::symlink_metadata(p).ok().map(|m| (p, m))) {
            Some((p, m)) => format!(" ({} is {})", p.display(), who(&m)),
            None => String::new(),
        }
    }

    fn check_folder(&self, path: &Path, m: &Metadata) -> Result<u32, String> {
        let p = path.display();
        if !m.file_type().is_dir() {
            return Err(format!(
                "iceoryx2's folder {p} is {} ({}): remove it as root (sudo rm {p}) and start again; {REMEDY}",
                kind(m),
                who(m)
            ));
        }
        let mode = m.mode() & 0o7777;
        if m.uid() == self.me.uid {
            // Ours: group-only, setgid, whatever made it (iceoryx2 makes 0750 folders).
            if mode != 0o2770 {
                fs::set_permissions(path, fs::Permissions::from_mode(0o2770))
                    .map_err(|e| format!("cannot restrict {p} to its group: {e}"))?;
            }
            return Ok(m.gid());
        }
        let shared = self.me.member_of(m.gid());
        if !(m.uid() == 0 || shared || self.me.is_root()) {
            let (owner, g, me) = (user(m.uid()), group(m.gid()), user(self.me.uid));
            return Err(format!(
                "{p} is owned by {owner}, group {g}, mode {mode:04o}; {me} is neither its owner, root, nor in group {g}: \
                 if {owner} runs the tracker, add this user to group {g} (sudo usermod -aG {g} USER); if not, \
                 another user's iceoryx2 process made it first: stop it, remove the folder as root (sudo rm -r {p}) \
                 and start again; {REMEDY}"
            ));
        }
        if mode & 0o007 != 0 {
            return Err(format!(
                "{p} ({}) is open to every user: remove it as root (sudo rm -r {p}) and start again; {REMEDY}",
                who(m)
            ));
        }
        if !self.me.is_root() && (!shared || mode & 0o070 != 0o070) {
            // Here the folder is root's, or its group may not write: made with iceoryx2's own
            // rights (0750) by a process that does not share.
            let why = if m.uid() == 0 {
                format!("a process of root made it first: remove it as root (sudo rm -r {p}) and start again; {REMEDY}")
            } else {
                format!(
                    "{} made it with iceoryx2's own rights (group read-only): the tracker, running as that user, opens it \
                     to its group when it starts; or remove it as root (sudo rm -r {p}) and start again; {REMEDY}",
                    user(m.uid())
                )
            };
            return Err(format!(
                "{p} ({}) cannot be written by {}: {why}",
                who(m),
                user(self.me.uid)
            ));
        }
        Ok(m.gid())
    }

    /// Whether a file of the domain may be used: this user's or root's, or given to the domain's
    /// group (which only its members and root can do).
    fn trusted(&self, m: &Metadata) -> bool {
        m.uid() == self.me.uid
            || m.uid() == 0
            || self.me.is_root()
            || (m.gid() == self.group && self.me.member_of(m.gid()))
    }

    fn foreign(&self, path: &Path, m: &Metadata) -> String {
        let p = path.display();
        format!(
            "{p} is owned by {} (group {}), not by {} or root, nor given to this domain's group {}: another user's \
             iceoryx2 process made it; stop it, remove the file as root (sudo rm {p}) and start again; {REMEDY}",
            user(m.uid()),
            group(m.gid()),
            user(self.me.uid),
            group(self.group)
        )
    }

    /// A node counter file: made group-only when missing (`make`), checked, and repaired when its
    /// content is wrong. Errors only where `make` (omnitrack's own file); the default one is
    /// repaired where possible and otherwise left alone.
    fn counter(&self, path: &Path, make: bool) -> Result<(), String> {
        let p = path.display();
        for _ in 0..2 {
            let m = match fs::symlink_metadata(path) {
                Ok(m) => m,
                Err(e) if e.kind() == ErrorKind::NotFound && make => {
                    // Made write-only and filled before anyone may read it, the way iceoryx2
                    // marks a file it is still making; then given to the group.
                    match OpenOptions::new()
                        .read(true)
                        .write(true)
                        .create_new(true)
                        .mode(0o200)
                        .open(path)
                    {
                        Ok(f) => {
                            return f
                                .write_all_at(&counter_bytes(0), 0)
                                .and_then(|()| std::os::unix::fs::fchown(&f, None, Some(self.group)))
                                .and_then(|()| f.set_permissions(fs::Permissions::from_mode(0o660)))
                                .map_err(|e| format!("making iceoryx2's node counter {p}: {e}"));
                        }
                        Err(e) if e.kind() == ErrorKind::AlreadyExists => continue,
                        Err(e) => return Err(format!("cannot make iceoryx2's node counter {p}: {e}")),
                    }
                }
                Err(e) if e.kind() == ErrorKind::NotFound => return Ok(()),
                Err(e) => return Err(format!("cannot look at {p}: {e}")),
            };
            return self.check_counter(path, m, make);
        }
        Err(format!("{p} keeps changing: another process makes and removes it"))
    }

    fn check_counter(&self, path: &Path, mut m: Metadata, ours: bool) -> Result<(), String> {
        let p = path.display();
        if !m.file_type().is_file() {
            return Err(format!(
                "iceoryx2's node counter {p} is {} ({}): remove it as root (sudo rm {p}) and start again",
                kind(&m),
                who(&m)
            ));
        }
        if !self.trusted(&m) {
            return Err(self.foreign(path, &m));
        }
        let mine = m.uid() == self.me.uid;
        if m.mode() & 0o007 != 0 {
            if !(ours && mine) {
                return Err(format!(
                    "iceoryx2's node counter {p} ({}) can be written by every user: remove it as root (sudo rm {p}) and \
                     start again; {REMEDY}",
                    who(&m)
                ));
            }
            fs::set_permissions(path, fs::Permissions::from_mode(m.mode() & 0o770 | 0o660))
                .map_err(|e| format!("cannot restrict {p} to its group: {e}"))?;
        }
        // Still being made by another process (iceoryx2 gives its owner read once the content is
        // there): wait for it as iceoryx2 would, but not for ever.
        let start = Instant::now();
        while m.mode() & 0o400 == 0 && !mine && start.elapsed() < HALF_MADE_WAIT {
            std::thread::sleep(Duration::from_millis(10));
            m = fs::symlink_metadata(path).map_err(|e| format!("{p}: {e}"))?;
        }
        if m.mode() & 0o400 == 0 && !mine {
            return Err(format!(
                "iceoryx2's node counter {p} ({}) was left half-made by a process that stopped: remove it as root (sudo \
                 rm {p}) and start again",
                who(&m)
            ));
        }
        let file = match OpenOptions::new().read(true).write(true).open(path) {
            Ok(f) => f,
            Err(e) if e.kind() == ErrorKind::PermissionDenied => {
                return Err(format!(
                    "iceoryx2's node counter {p} ({}) cannot be written by {}: remove it as root (sudo rm {p}) and \
                     start again; {REMEDY}",
                    who(&m),
                    user(self.me.uid)
                ))
            }
            Err(e) => return Err(format!("cannot open iceoryx2's node counter {p}: {e}")),
        };
        // The file opened is the one looked at (the folder is sticky: only its owner could have
        // swapped it, and that owner is trusted).
        let opened = file.metadata().map_err(|e| format!("{p}: {e}"))?;
        if opened.ino() != m.ino() || opened.dev() != m.dev() {
            return Err(format!("{p} was replaced while it was checked: start again"));
        }
        repair_counter(&file).map_err(|e| format!("cannot repair iceoryx2's node counter {p}: {e}"))?;
        if mine && m.mode() & 0o400 == 0 {
            fs::set_permissions(path, fs::Permissions::from_mode(0o660))
                .map_err(|e| format!("cannot finish iceoryx2's node counter {p}: {e}"))?;
        }
        Ok(())
    }

    /// Gives every file and folder this user owns in the domain to the domain's group, with the
    /// owner's rights mirrored to the group and none for others: what iceoryx2 just made for this
    /// process's node and ports becomes reachable for the tracker and the consumers in its
    /// group, and for no one else. A file still being made (owner-write only) is left as it is.
    /// Run after making ports; never on the pose path (it reads folders).
    pub fn share_with_group(&self) -> Result<(), String> {
        self.share_tree(&self.root, 0)?;
        let entries = match fs::read_dir(SHM_DIR) {
            Ok(entries) => entries,
            Err(e) => return Err(format!("cannot list {SHM_DIR}: {e}")),
        };
        for entry in entries.flatten() {
            let name = entry.file_name();
            if !name.as_bytes().starts_with(self.prefix.as_bytes()) {
                continue;
            }
            let path = entry.path();
            // iceoryx2's own counter file is every default-config process's: its rights are
            // left to the deployment (tools/deploy).
            if path == self.their_counter {
                continue;
            }
            self.share(&path)?;
        }
        Ok(())
    }

    fn share_tree(&self, dir: &Path, depth: usize) -> Result<(), String> {
        let Some(m) = self.share(dir)? else { return Ok(()) };
        if !m.file_type().is_dir() || depth > 3 {
            return Ok(());
        }
        let entries = match fs::read_dir(dir) {
            Ok(entries) => entries,
            Err(e) if e.kind() == ErrorKind::NotFound || e.kind() == ErrorKind::PermissionDenied => return Ok(()),
            Err(e) => return Err(format!("cannot list {}: {e}", dir.display())),
        };
        for entry in entries.flatten() {
            self.share_tree(&entry.path(), depth + 1)?;
        }
        Ok(())
    }

    /// Shares one entry if this user owns it; returns its metadata (`None` when it is gone).
    fn share(&self, path: &Path) -> Result<Option<Metadata>, String> {
        let m = match fs::symlink_metadata(path) {
            Ok(m) => m,
            Err(e) if e.kind() == ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(format!("cannot look at {}: {e}", path.display())),
        };
        let mode = m.mode() & 0o7777;
        if m.uid() != self.me.uid || m.file_type().is_symlink() || mode & 0o400 == 0 {
            return Ok(Some(m));
        }
        // A regular file of 0600 in the root folder is either a node's monitor (whose lock tells
        // the node's death: kept private, so that only its own user, restarting, cleans up after a
        // crash, never a consumer that could not remove another user's files in /dev/shm and
        // would leave them behind) or a static file iceoryx2 is still writing (0600 until done).
        if mode == 0o600 && m.file_type().is_file() && path.starts_with(&self.root) {
            return Ok(Some(m));
        }
        let owner = mode & 0o700;
        let mut want = (mode & 0o7700) | (owner >> 3);
        if m.file_type().is_dir() {
            want |= 0o2000;
        }
        let gone = |e: &std::io::Error| e.kind() == ErrorKind::NotFound;
        if m.gid() != self.group {
            // Before the rights: changing the group clears a file's setgid bit, not a folder's.
            if let Err(e) = std::os::unix::fs::lchown(path, None, Some(self.group)) {
                if gone(&e) {
                    return Ok(None);
                }
                return Err(format!(
                    "cannot give {} to group {}: {e}",
                    path.display(),
                    group(self.group)
                ));
            }
        }
        if want != mode {
            if let Err(e) = fs::set_permissions(path, fs::Permissions::from_mode(want)) {
                if gone(&e) {
                    return Ok(None);
                }
                return Err(format!("cannot share {} with its group: {e}", path.display()));
            }
        }
        Ok(Some(m))
    }

    /// After a failure: the first file of the domain held by a user this process does not trust,
    /// as a clause for the error line, or empty.
    pub fn foreign_files(&self) -> String {
        let mut found: Vec<(PathBuf, Metadata)> = Vec::new();
        self.find_foreign(&self.root, 0, &mut found);
        if let Ok(entries) = fs::read_dir(SHM_DIR) {
            for entry in entries.flatten() {
                let path = entry.path();
                if !entry.file_name().as_bytes().starts_with(self.prefix.as_bytes()) || path == self.their_counter {
                    continue;
                }
                if let Ok(m) = fs::symlink_metadata(&path) {
                    if !self.trusted(&m) {
                        found.push((path, m));
                    }
                }
            }
        }
        match found.first() {
            None => String::new(),
            Some((path, m)) => format!(
                "; {} file(s) of other users are in the way, e.g. {} ({}): stop their processes, or remove them as root",
                found.len(),
                path.display(),
                who(m)
            ),
        }
    }

    fn find_foreign(&self, dir: &Path, depth: usize, found: &mut Vec<(PathBuf, Metadata)>) {
        let Ok(entries) = fs::read_dir(dir) else { return };
        for entry in entries.flatten() {
            let path = entry.path();
            let Ok(m) = fs::symlink_metadata(&path) else { continue };
            if !self.trusted(&m) {
                found.push((path.clone(), m.clone()));
            }
            if m.file_type().is_dir() && depth < 3 {
                self.find_foreign(&path, depth + 1, found);
            }
        }
    }
}

/// The counter file's content as iceoryx2 0.10 writes it: the version word, then the counter.
fn counter_bytes(counter: u32) -> [u8; COUNTER_BYTES] {
    let mut b = [0u8; COUNTER_BYTES];
    b[..8].copy_from_slice(&COUNTER_VERSION.to_le_bytes());
    b[8..12].copy_from_slice(&counter.to_le_bytes());
    b
}

/// Rewrites a counter file whose content iceoryx2 would refuse (a wrong version: "unable to
/// generate a unique node id") or wait on for ever (shorter than its content: zero length is
/// never taken as made). The counter only breaks ties between nodes made in the same nanosecond
/// by the same pid, so keeping whatever value it holds, or zero, is safe for the nodes alive.
fn repair_counter(file: &File) -> std::io::Result<bool> {
    let mut head = [0u8; COUNTER_BYTES];
    let mut read = 0;
    // At its offset, not the file's position: the check may run again on the same open file.
    while read < COUNTER_BYTES {
        match file.read_at(&mut head[read..], read as u64)? {
            0 => break,
            n => read += n,
        }
    }
    let version = u64::from_le_bytes(head[..8].try_into().unwrap_or([0; 8]));
    if read == COUNTER_BYTES && version == COUNTER_VERSION {
        return Ok(false);
    }
    if read < COUNTER_BYTES {
        file.set_len(COUNTER_BYTES as u64)?;
    }
    let counter = if read >= 12 {
        u32::from_le_bytes(head[8..12].try_into().unwrap_or([0; 4]))
    } else {
        0
    };
    file.write_all_at(&counter_bytes(counter), 0)?;
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_counter_file_is_repaired_whatever_was_done_to_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("counter");
        for damage in [&[][..], &[0xff; 16][..], &[1, 2, 3][..], &[0; 16][..]] {
            fs::write(&path, damage).unwrap();
            let f = OpenOptions::new().read(true).write(true).open(&path).unwrap();
            assert!(repair_counter(&f).unwrap(), "{damage:?}");
            let bytes = fs::read(&path).unwrap();
            assert_eq!(bytes.len(), COUNTER_BYTES);
            assert_eq!(&bytes[..8], &COUNTER_VERSION.to_le_bytes());
            assert!(!repair_counter(&f).unwrap(), "repaired twice: {damage:?}");
        }
        // A sound file keeps its count.
        fs::write(&path, counter_bytes(41)).unwrap();
        let f = OpenOptions::new().read(true).write(true).open(&path).unwrap();
        assert!(!repair_counter(&f).unwrap());
        assert_eq!(fs::read(&path).unwrap(), counter_bytes(41));
    }

    #[test]
    fn this_process_knows_its_user_and_groups() {
        let me = Identity::of_this_process().unwrap();
        let proc_self = fs::metadata("/proc/self").unwrap();
        assert_eq!(me.uid, proc_self.uid());
        assert!(me.member_of(me.gid));
        assert!(user(0).starts_with("root (uid 0)") || user(0) == "uid 0");
    }
}
