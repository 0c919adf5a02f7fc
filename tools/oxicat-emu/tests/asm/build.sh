#!/bin/sh
# Assembles the test programs into the ELF images tests/integration/exceptions.rs loads (committed, so
# the tests need no assembler). Needs llvm-mc and an ELF linker (ld.lld or rust-lld).
set -e
cd "$(dirname "$0")"
LD=$(find "$(rustc --print sysroot)" -name rust-lld | head -1)
for s in *.s; do
  n=${s%.s}
  llvm-mc -triple=thumbv7em-none-eabihf -mattr=+vfp4d16sp -filetype=obj "$s" -o "$n.o"
  "$LD" -flavor gnu -N -T link.ld -e vectors --build-id=none -o "$n.elf" "$n.o"
  rm -f "$n.o"
done
