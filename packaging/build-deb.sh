#!/usr/bin/env bash
# Builds the Debian package (binary, desktop entry, AppStream metainfo, icons)
# with cargo-deb, installing cargo-deb first when it is missing. The package
# lands in target/debian/.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! cargo deb --version >/dev/null 2>&1; then
  echo "build-deb: installing cargo-deb"
  cargo install cargo-deb --locked --quiet
fi
cargo deb "$@"
ls -l target/debian/*.deb
