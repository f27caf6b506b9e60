"""Builds the Blender extension zip: the render engine and exporter (`logsh_exporter/`)
with the logsh binary for this platform, so that the machine that installs it needs no
Rust toolchain.

    python3 blender_scripts/build_extension.py [--binary PATH] [--out DIR]

builds the crate (`cargo build --release`) unless `--binary` names a logsh already built,
and writes `DIR/logsh-VERSION-PLATFORM.zip` (DIR: `target/extension`), laid out as
`blender --command extension build` lays an extension out: the manifest at the top, with
`platforms` set to the binary's platform, and the binary as `bin/logsh`. Install it with
Edit > Preferences > Get Extensions > Install from Disk, or
`blender --command extension install-file -r user_default ZIP`.

For another platform, run this script there (a macOS or Windows build of the crate; the
platform is the one Python runs on). Without a carried binary (the add-on folder zipped
as it is), the engine takes `logsh` from PATH or from the add-on's preferences.

The zip is checked by Blender's own `extension validate`: `blender --command extension
validate` where `blender` is on PATH, else the validator pip's bpy ships when this script
runs in a Python that has it (`.venv-bpy/bin/python`); without either, by the checks of it
that concern this zip (the manifest's required fields, the id, the platform, nothing
outside the package).
"""
import argparse
import glob
import importlib.util
import os
import platform
import re
import shutil
import stat
import subprocess
import sys
import tomllib
import zipfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE = os.path.join(ROOT, "blender_scripts", "logsh_exporter")
REQUIRED = ("schema_version", "id", "version", "name", "tagline", "maintainer", "type", "license",
            "blender_version_min")
PLATFORMS = {("Linux", "x86_64"): "linux-x64", ("Linux", "aarch64"): "linux-arm64",
             ("Darwin", "arm64"): "macos-arm64", ("Darwin", "x86_64"): "macos-x64",
             ("Windows", "AMD64"): "windows-x64", ("Windows", "ARM64"): "windows-arm64"}


class BuildError(Exception):
    pass


def this_platform():
    key = (platform.system(), platform.machine())
    if key not in PLATFORMS:
        raise BuildError(f"no Blender platform name for {key[0]} on {key[1]}")
    return PLATFORMS[key]


def build_binary():
    """Builds the crate in release mode; returns the binary's path."""
    try:
        subprocess.run(["cargo", "build", "--release", "--bin", "logsh"], cwd=ROOT, check=True)
    except (OSError, subprocess.CalledProcessError) as e:
        raise BuildError(f"cargo build --release failed ({e}); pass --binary to use a logsh built elsewhere")
    return os.path.join(ROOT, "target", "release", "logsh" + (".exe" if os.name == "nt" else ""))


def package_files():
    """The package's files (relative paths), without caches."""
    for folder, directories, files in os.walk(PACKAGE):
        directories[:] = [d for d in directories if d != "__pycache__"]
        for name in sorted(files):
            if not name.endswith((".pyc", ".pyo")):
                yield os.path.relpath(os.path.join(folder, name), PACKAGE)


def manifest_with_platform(text, platform_name):
    """The manifest with `platforms = [platform_name]` (replacing any `platforms` line)."""
    lines = [line for line in text.splitlines() if not line.startswith("platforms")]
    at = next(i for i, line in enumerate(lines) if line.startswith("blender_version_min")) + 1
    lines.insert(at, f'platforms = ["{platform_name}"]')
    return "\n".join(lines) + "\n"


def check_manifest(manifest, names):
    """The checks of Blender's `extension validate` that concern this zip."""
    missing = [key for key in REQUIRED if key not in manifest]
    if missing:
        raise BuildError(f"blender_manifest.toml: missing {', '.join(missing)}")
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", manifest["id"]):
        raise BuildError(f"blender_manifest.toml: id {manifest['id']!r} is not a Python identifier")
    if manifest["type"] != "add-on" or not isinstance(manifest["license"], list):
        raise BuildError("blender_manifest.toml: type must be add-on and license a list")
    for name in manifest.get("platforms", []):
        if name not in PLATFORMS.values():
            raise BuildError(f"blender_manifest.toml: unknown platform {name}")
    if "__init__.py" not in names or "blender_manifest.toml" not in names:
        raise BuildError("the zip lacks __init__.py or blender_manifest.toml at its top")
    for name in names:
        if name.startswith("/") or ".." in name.split("/"):
            raise BuildError(f"the zip holds {name}, outside the package")


def build(binary, out):
    if not os.path.isfile(binary):
        raise BuildError(f"{binary}: no such binary")
    platform_name = this_platform()
    with open(os.path.join(PACKAGE, "blender_manifest.toml"), "rb") as f:
        text = f.read().decode()
    manifest_text = manifest_with_platform(text, platform_name)
    manifest = tomllib.loads(manifest_text)
    os.makedirs(out, exist_ok=True)
    path = os.path.join(out, f"logsh-{manifest['version']}-{platform_name}.zip")
    partial = path + ".partial"
    with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as z:
        for name in package_files():
            if name == "blender_manifest.toml":
                z.writestr(name, manifest_text)
            else:
                z.write(os.path.join(PACKAGE, name), name.replace(os.sep, "/"))
        entry = zipfile.ZipInfo("bin/logsh" + (".exe" if binary.endswith(".exe") else ""))
        entry.external_attr = (stat.S_IFREG | 0o755) << 16
        entry.compress_type = zipfile.ZIP_DEFLATED
        with open(binary, "rb") as f:
            z.writestr(entry, f.read())
        names = z.namelist()
    try:
        check_manifest(manifest, names)
    except BuildError:
        os.remove(partial)
        raise
    validator = blender_validator()
    if validator is not None:
        checked = subprocess.run(validator + [partial], capture_output=True, text=True)
        if checked.returncode != 0:
            os.remove(partial)
            raise BuildError(f"{' '.join(validator)}: {(checked.stdout + checked.stderr).strip()}")
    os.replace(partial, path)
    return path


def blender_validator():
    """Blender's own `extension validate` (module doc), or None."""
    blender = shutil.which("blender")
    if blender:
        return [blender, "--command", "extension", "validate"]
    spec = importlib.util.find_spec("bpy")
    for folder in (spec.submodule_search_locations or []) if spec else []:
        found = glob.glob(os.path.join(folder, "*", "scripts", "addons_core", "bl_pkg", "cli", "blender_ext.py"))
        if found:
            return [sys.executable, found[0], "validate"]
    return None


def main(argv):
    parser = argparse.ArgumentParser(prog="build_extension.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--binary", help="a logsh binary already built (default: cargo build --release)")
    parser.add_argument("--out", default=os.path.join(ROOT, "target", "extension"), help="output directory")
    args = parser.parse_args(argv)
    try:
        path = build(args.binary or build_binary(), args.out)
    except BuildError as e:
        sys.exit(f"error: {e}")
    print(path)


if __name__ == "__main__":
    main(sys.argv[1:])
