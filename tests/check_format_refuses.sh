#!/usr/bin/env bash
# The formatting check can fail: in a scratch git repository holding
# scripts/format and .clang-format, a formatted file passes, and a file with
# a line over the column limit, or one clang-format would change, is refused
# (exit 1) and named; --fix refuses (and leaves untouched) a file that is
# not C++ or .proto. Exit 77 (skipped) without clang-format-14.
set -euo pipefail
ROOT="$1"
command -v "${CLANG_FORMAT:-clang-format-14}" >/dev/null || exit 77
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/scripts"
cp "$ROOT/scripts/format" "$work/scripts/format"
cp "$ROOT/.clang-format" "$work/.clang-format"
cd "$work"
git init -q . && git config user.email t@t && git config user.name t
printf 'int Add(int a, int b) { return a + b; }\n' > good.cc
git add -A && git commit -qm good
scripts/format --all >/dev/null || { echo "a formatted file was refused"; exit 1; }

expect_refused() {  # FILE CONTENT
  printf '%s' "$2" > "$1"
  git add -A && git commit -qm "$1"
  if out="$(scripts/format --all)"; then
    echo "not refused: $1"; exit 1
  fi
  grep -q "^$1 " <<<"$out" || { echo "refusal does not name $1: $out"; exit 1; }
  git rm -q "$1" && git commit -qm "rm $1"
}
expect_refused long.h "// $(printf 'x%.0s' $(seq 1 90))
"
expect_refused spacing.cc 'int  Sub( int a,int b ){return a-b;}
'
# --fix leaves a non-C++ file untouched and says so (it would otherwise
# rewrite a shell script as C++).
script='#!/usr/bin/env bash
echo  "keep   these  spaces"
'
printf '%s' "$script" > tool.sh
chmod +x tool.sh
if scripts/format --fix tool.sh 2>/dev/null; then
  echo "--fix accepted a shell script"; exit 1
fi
[ "$(cat tool.sh)" = "$(printf '%s' "$script")" ] && [ -x tool.sh ] ||
  { echo "--fix changed tool.sh"; exit 1; }
echo "format check refuses both files; --fix leaves a shell script alone"
