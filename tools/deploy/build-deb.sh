#!/usr/bin/env bash
# The Debian package of the tracker for the rig's computer, in one command:
#
#   tools/deploy/build-deb.sh
#
# writes target/debian/omnitrack_<version>-1_<arch>.deb: the `omnitrack` binary built with both
# camera features (v4l: V4L2, usb: USB3 Vision) and without the desk code, its systemd unit, udev
# rules, tmpfiles and sysusers files, shell completions and a manual page per command, and
# /etc/omnitrack with the shipped rig.toml and tracker.toml (Cargo.toml, [package.metadata.deb];
# docs/rig-guide.md, "The Debian package"). Install it with
# `sudo apt install ./target/debian/omnitrack_*.deb`.
#
# What it needs, and gets if missing, saying so: libclang (the v4l crate generates its V4L2
# bindings with bindgen at build time, and v4l 0.14 offers no pre-generated ones), installed with
# apt-get; cargo-deb, installed with `cargo install cargo-deb --locked`.
#
#   tools/deploy/build-deb.sh --binary target/debug/omnitrack
#
# packages a binary built already (CI: the one its --all-features step built, which has both
# camera features) with the fast compression, instead of building one.
set -euo pipefail
cd "$(dirname "$0")/../.."

binary=""
case "${1:-}" in
  "") ;;
  --binary) binary="${2:?--binary needs the path of an omnitrack binary}" ;;
  *) echo "build-deb.sh: unknown argument $1 (see the comment at the top of $0)" >&2; exit 2 ;;
esac
target="${CARGO_TARGET_DIR:-target}"

if [ -z "$binary" ]; then
  if ! tools/deploy/have-libclang.sh; then
    echo "build-deb.sh: the v4l feature's bindgen needs libclang, which is missing: installing it with apt-get" >&2
    SUDO=""
    if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
    $SUDO apt-get update -qq
    # libclang1-14 is all bindgen needs on Debian 12; elsewhere the generic development package.
    $SUDO apt-get install -y --no-install-recommends libclang1-14 \
      || $SUDO apt-get install -y --no-install-recommends libclang-dev
  fi
  cargo build --locked --release -p omnitrack --no-default-features --features v4l,usb
  profile=release
  fast=()
else
  # A profile of cargo-deb's own naming: it packages what is in $target/deb-staged/.
  profile=deb-staged
  fast=(--fast)
  rm -rf "$target/$profile"
  mkdir -p "$target/$profile"
  cp "$binary" "$target/$profile/omnitrack"
fi
if ! command -v cargo-deb >/dev/null 2>&1; then
  echo "build-deb.sh: cargo-deb is missing: installing it (cargo install cargo-deb --locked)" >&2
  cargo install cargo-deb --locked
fi

# Completions and manual pages from the binary itself, beside it, where the package's assets
# name them (target/release/share/ in Cargo.toml is this build's directory).
bin="$target/$profile/omnitrack"
share="$target/$profile/share"
rm -rf "$share"
mkdir -p "$share/completions"
for shell in bash zsh fish; do
  "$bin" completions "$shell" > "$share/completions/omnitrack.$shell"
done
"$bin" manpage --dir "$share/man/man1" 2>/dev/null
gzip -9n "$share"/man/man1/*.1

cargo deb --locked -p omnitrack --no-build --profile "$profile" ${fast[@]+"${fast[@]}"} \
  --output "$target/debian/"
