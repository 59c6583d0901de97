#!/usr/bin/env bash
# Exits 0 when libclang, which bindgen (the v4l feature's build step) loads, is installed.
compgen -G '/usr/lib/llvm-*/lib/libclang.so*' >/dev/null \
  || compgen -G '/usr/lib/*/libclang.so*' >/dev/null \
  || compgen -G '/usr/lib/*/libclang-[0-9]*.so*' >/dev/null
