//! Who this process is and how the error lines name users, groups and files: the identity the
//! domain checks are made against, and the words for what stands in the way.
//!
//! In: `/proc/self/status`, `/etc/passwd`, `/etc/group`, a file's metadata. Out: an [`Identity`]
//! (effective user, group, supplementary groups) and the names used in one-line errors.

use std::fs::{self, Metadata};
use std::os::unix::fs::{FileTypeExt, MetadataExt};

/// The user and groups this process acts as.
#[derive(Debug, Clone)]
pub(super) struct Identity {
    pub(super) uid: u32,
    pub(super) gid: u32,
    pub(super) groups: Vec<u32>,
}

impl Identity {
    pub(super) fn of_this_process() -> Result<Self, String> {
        let status = fs::read_to_string("/proc/self/status")
            .map_err(|e| format!("cannot read /proc/self/status for this process's user: {e}"))?;
        let field = |key: &str| -> Vec<u32> {
            status
                .lines()
                .find_map(|l| l.strip_prefix(key))
                .map(|rest| rest.split_whitespace().filter_map(|n| n.parse().ok()).collect())
                .unwrap_or_default()
        };
        // Real, effective, saved, filesystem: files are made and checked as the effective ones.
        let (uid, gid) = match (field("Uid:").get(1), field("Gid:").get(1)) {
            (Some(&u), Some(&g)) => (u, g),
            _ => return Err("cannot read this process's user from /proc/self/status".into()),
        };
        Ok(Identity {
            uid,
            gid,
            groups: field("Groups:"),
        })
    }

    pub(super) fn is_root(&self) -> bool {
        self.uid == 0
    }

    pub(super) fn member_of(&self, gid: u32) -> bool {
        self.gid == gid || self.groups.contains(&gid)
    }
}

/// `name (uid N)` from /etc/passwd, or `uid N`.
pub(super) fn user(uid: u32) -> String {
    match name_in("/etc/passwd", uid) {
        Some(name) => format!("{name} (uid {uid})"),
        None => format!("uid {uid}"),
    }
}

/// The group's name from /etc/group, or its number.
pub(super) fn group(gid: u32) -> String {
    name_in("/etc/group", gid).unwrap_or_else(|| gid.to_string())
}

fn name_in(file: &str, id: u32) -> Option<String> {
    let text = fs::read_to_string(file).ok()?;
    text.lines().find_map(|l| {
        let mut f = l.split(':');
        let name = f.next()?;
        (f.nth(1)?.parse::<u32>().ok()? == id).then(|| name.to_string())
    })
}

pub(super) fn kind(m: &Metadata) -> &'static str {
    let t = m.file_type();
    if t.is_dir() {
        "a folder"
    } else if t.is_symlink() {
        "a symbolic link"
    } else if t.is_socket() {
        "a socket"
    } else if t.is_file() {
        "a file"
    } else {
        "a device or FIFO"
    }
}

pub(super) fn who(m: &Metadata) -> String {
    format!(
        "{}, group {}, mode {:04o}",
        user(m.uid()),
        group(m.gid()),
        m.mode() & 0o7777
    )
}
