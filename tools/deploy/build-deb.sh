#!/usr/bin/env bash
# The Debian packages of omnitrack for the rig's computer, in one command:
#
#   tools/deploy/build-deb.sh
#
# writes into target/debian/ one package per program (docs/decisions.md says why four, not one;
# docs/rig-guide.md, "The Debian package", lists their files):
#
#   omnitrack_<version>-1_<arch>.deb       the tracker, built with both camera features (v4l:
#                                          V4L2, usb: USB3 Vision) and without the desk code, its
#                                          systemd unit, udev rules, tmpfiles and sysusers files,
#                                          and /etc/omnitrack with the shipped rig and tunables
#   omnitrack-view_<version>-1_<arch>.deb  the live view in Foxglove and `run --mcap`'s writer
#   omnitrack-link_<version>-1_<arch>.deb  poses to other hosts over Zenoh
#   omnitrack-ros2_<version>-1_<arch>.deb  poses to ROS 2 over DDS, no ROS installation needed
#
# each with its program's shell completions and a manual page per command (each crate's
# Cargo.toml, [package.metadata.deb]), and beside each a PROGRAM-dbgsym_….ddeb with the
# program's debug information (install it for backtraces with file and line). Install what the rig needs, e.g. all of them with
# `sudo apt install ./target/debian/omnitrack*.deb`.
#
# What it needs, and gets if missing, saying so: libclang (the v4l crate generates its V4L2
# bindings with bindgen at build time, and v4l 0.14 offers no pre-generated ones), installed with
# apt-get; cargo-deb, installed with `cargo install cargo-deb --locked`. omnitrack-ros2 needs Rust
# 1.88 (RustDDS): with an older toolchain its package is left out, in one line saying so.
#
#   tools/deploy/build-deb.sh --binary target/debug/omnitrack [--binary PATH]...
#
# packages programs built already (CI: the binaries its test steps built, so that nothing is
# compiled twice), each into the package of its file name, with the fast compression.
set -euo pipefail
cd "$(dirname "$0")/../.."

binaries=()
while [ $# -gt 0 ]; do
  case "$1" in
    --binary) binaries+=("${2:?--binary needs the path of a built omnitrack program}"); shift 2 ;;
    *) echo "build-deb.sh: unknown argument $1 (see the comment at the top of $0)" >&2; exit 2 ;;
  esac
done
target="${CARGO_TARGET_DIR:-target}"
# The package of each program: the crate whose [package.metadata.deb] packages it.
known="omnitrack omnitrack-view omnitrack-link omnitrack-ros2"

if [ ${#binaries[@]} -eq 0 ]; then
  if ! tools/deploy/have-libclang.sh; then
    echo "build-deb.sh: the v4l feature's bindgen needs libclang, which is missing: installing it with apt-get" >&2
    SUDO=""
    if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
    $SUDO apt-get update -qq
    # libclang1-14 is all bindgen needs on Debian 12; elsewhere the generic development package.
    $SUDO apt-get install -y --no-install-recommends libclang1-14 \
      || $SUDO apt-get install -y --no-install-recommends libclang-dev
  fi
  programs=(omnitrack omnitrack-view omnitrack-link)
  rustc_minor="$(rustc --version | sed -n 's/^rustc 1\.\([0-9]*\).*/\1/p')"
  if [ "${rustc_minor:-0}" -ge 88 ]; then
    programs+=(omnitrack-ros2)
  else
    echo "build-deb.sh: omnitrack-ros2 needs Rust 1.88 or newer ($(rustc --version)): its package is left out (rustup update, then run this again)" >&2
  fi
  # One cargo command, so that what the programs share (omnitrack-io, iceoryx2, clap, ...) is
  # built once. The camera features are the tracker's; its desk code stays out.
  packages=()
  for p in "${programs[@]}"; do packages+=(-p "$p"); done
  cargo build --locked --release "${packages[@]}" --no-default-features --features omnitrack/v4l,omnitrack/usb
  profile=release
  # Stripped programs in the packages, their debug information (line tables, for backtraces)
  # in a PROGRAM-dbgsym .ddeb beside each, as Debian's own packages do: a fifth of the size.
  fast=(--dbgsym)
else
  # A profile of cargo-deb's own naming: it packages what is in $target/deb-staged/.
  profile=deb-staged
  fast=(--fast)
  rm -rf "${target:?}/$profile"
  mkdir -p "$target/$profile"
  programs=()
  for binary in "${binaries[@]}"; do
    name="$(basename "$binary")"
    case " $known " in
      *" $name "*) ;;
      *) echo "build-deb.sh: $binary: no package holds a program of that name (one of: $known)" >&2; exit 2 ;;
    esac
    [ -x "$binary" ] || { echo "build-deb.sh: $binary: no such program (build it first)" >&2; exit 2; }
    cp "$binary" "$target/$profile/$name"
    programs+=("$name")
  done
fi
if ! command -v cargo-deb >/dev/null 2>&1; then
  echo "build-deb.sh: cargo-deb is missing: installing it (cargo install cargo-deb --locked)" >&2
  cargo install cargo-deb --locked
fi

for program in "${programs[@]}"; do
  # Completions and manual pages from the program itself, beside it, where its package's assets
  # name them (target/release/share/PROGRAM/ in its Cargo.toml is this build's directory).
  bin="$target/$profile/$program"
  share="$target/$profile/share/$program"
  rm -rf "$share"
  mkdir -p "$share/completions"
  for shell in bash zsh fish; do
    "$bin" completions "$shell" > "$share/completions/$program.$shell"
  done
  "$bin" manpage --dir "$share/man1" 2>/dev/null
  gzip -9n "$share"/man1/*.1
  cargo deb --locked -p "$program" --no-build --profile "$profile" ${fast[@]+"${fast[@]}"} \
    --output "$target/debian/"
done
