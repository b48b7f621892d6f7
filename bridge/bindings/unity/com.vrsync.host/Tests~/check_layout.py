"""Checks the layout of the Unity package com.vrsync.host (Python 3 standard library only):

- package.json parses as JSON and has Unity's required fields (name in reverse-domain
  lowercase, semantic version, unity "YYYY.N", displayName, description, keywords) and each
  sample's path exists under Samples~;
- every asmdef parses and has a name; the Runtime one allows unsafe code;
- every file and folder Unity imports (names not ending in "~", not starting with ".") has a
  .meta beside it, and every .meta has its asset -- except the native plugin's, whose library
  build-plugin.sh places; each .meta's importer fits its asset (folders, C# scripts, asmdefs,
  package.json, text);
- every GUID is 32 lowercase hex digits and unique in the package;
- the native plugin's PluginImporter enables exactly the editor on Linux x86_64 and the
  standalone Linux x86_64 player.

usage: python3 check_layout.py PACKAGE_DIR [--fix]
  --fix  writes the missing .meta files (new GUIDs) first, for a maintainer adding files
Exit 0 when everything holds; the problems are listed otherwise.
"""

import json
import re
import sys
import uuid
from pathlib import Path

PLUGIN = "Runtime/Plugins/x86_64/libvrsync_host.so"

FOLDER_META = """fileFormatVersion: 2
guid: {guid}
folderAsset: yes
DefaultImporter:
  externalObjects: {{}}
  userData: 
  assetBundleName: 
  assetBundleVariant: 
"""
SCRIPT_META = """fileFormatVersion: 2
guid: {guid}
MonoImporter:
  externalObjects: {{}}
  serializedVersion: 2
  defaultReferences: []
  executionOrder: 0
  icon: {{instanceID: 0}}
  userData: 
  assetBundleName: 
  assetBundleVariant: 
"""
SIMPLE_META = """fileFormatVersion: 2
guid: {guid}
{importer}:
  externalObjects: {{}}
  userData: 
  assetBundleName: 
  assetBundleVariant: 
"""


def importer_for(path: Path) -> str:
    if path.is_dir():
        return "DefaultImporter"
    if path.suffix == ".cs":
        return "MonoImporter"
    if path.suffix == ".asmdef":
        return "AssemblyDefinitionImporter"
    if path.name == "package.json":
        return "PackageManifestImporter"
    if path.suffix in (".md", ".txt", ".json", ".toml"):
        return "TextScriptImporter"
    if path.suffix == ".so":
        return "PluginImporter"
    return "DefaultImporter"


def meta_text(path: Path) -> str:
    guid = uuid.uuid4().hex
    if path.is_dir():
        return FOLDER_META.format(guid=guid)
    if path.suffix == ".cs":
        return SCRIPT_META.format(guid=guid)
    return SIMPLE_META.format(guid=guid, importer=importer_for(path))


def imported(package: Path):
    """Every path under the package that Unity imports (hidden ones and .meta excluded)."""
    for p in sorted(package.rglob("*")):
        rel = p.relative_to(package)
        if any(part.endswith("~") or part.startswith(".") for part in rel.parts):
            continue
        if p.suffix == ".meta":
            continue
        yield p


def plugin_platforms(text: str) -> dict[str, dict[str, str]]:
    """platformData of a PluginImporter: {'Editor: Editor': {'enabled': '1', 'CPU': ...}}."""
    platforms: dict[str, dict[str, str]] = {}
    blocks = re.split(r"\n  - first:\n", text.split("platformData:", 1)[1].split("\n  userData:", 1)[0])
    for block in blocks[1:]:
        lines = block.split("\n")
        key = lines[0].strip()
        values = {}
        for line in lines[1:]:
            m = re.match(r"\s+([A-Za-z][A-Za-z0-9 ]*):\s*(.*)$", line)
            if m and m.group(1) not in ("second", "settings"):
                values[m.group(1)] = m.group(2).strip()
        platforms[key] = values
    return platforms


def main() -> int:
    args = sys.argv[1:]
    fix = "--fix" in args
    args = [a for a in args if a != "--fix"]
    if len(args) != 1:
        print(__doc__, file=sys.stderr)
        return 2
    package = Path(args[0]).resolve()
    problems: list[str] = []

    def problem(text: str) -> None:
        problems.append(text)

    # package.json
    try:
        manifest = json.loads((package / "package.json").read_text())
    except (OSError, ValueError) as e:
        problem(f"package.json: {e}")
        manifest = {}
    for key in ("name", "version", "displayName", "description", "unity", "keywords"):
        if key not in manifest:
            problem(f"package.json: no {key!r}")
    if not re.fullmatch(r"com(\.[a-z0-9][a-z0-9-]*){2,}", manifest.get("name", "")):
        problem(f"package.json: name {manifest.get('name')!r} is not reverse-domain lowercase (com.company.package)")
    if not re.fullmatch(r"\d+\.\d+\.\d+(-[0-9A-Za-z.-]+)?", manifest.get("version", "")):
        problem(f"package.json: version {manifest.get('version')!r} is not semantic (MAJOR.MINOR.PATCH)")
    if not re.fullmatch(r"\d{4}\.\d+", manifest.get("unity", "")):
        problem(f"package.json: unity {manifest.get('unity')!r} is not YYYY.N")
    if not isinstance(manifest.get("keywords", []), list):
        problem("package.json: keywords is not a list")
    for sample in manifest.get("samples", []):
        path = sample.get("path", "")
        if not path.startswith("Samples~/") or not (package / path).is_dir():
            problem(f"package.json: sample path {path!r} is not a folder under Samples~")

    # asmdefs
    asmdefs = [p for p in imported(package) if p.suffix == ".asmdef"]
    if not any(p.parent == package / "Runtime" for p in asmdefs):
        problem("Runtime/ has no assembly definition")
    for p in asmdefs:
        try:
            asm = json.loads(p.read_text())
        except ValueError as e:
            problem(f"{p.relative_to(package)}: {e}")
            continue
        if not asm.get("name"):
            problem(f"{p.relative_to(package)}: no name")
        if p.parent == package / "Runtime" and asm.get("allowUnsafeCode") is not True:
            problem(f"{p.relative_to(package)}: allowUnsafeCode is not true (the binding uses pointers)")

    # .meta files
    if fix:
        for p in imported(package):
            meta = p.with_name(p.name + ".meta")
            if not meta.exists():
                meta.write_text(meta_text(p))
                print(f"wrote {meta.relative_to(package)}")
    guids: dict[str, Path] = {}
    for p in imported(package):
        rel = p.relative_to(package)
        meta = p.with_name(p.name + ".meta")
        if not meta.exists():
            problem(f"{rel}: no .meta (run check_layout.py PACKAGE --fix)")
            continue
        text = meta.read_text()
        if p.is_dir() and "folderAsset: yes" not in text:
            problem(f"{rel}.meta: not a folder's .meta")
        want = importer_for(p)
        if f"\n{want}:" not in text:
            problem(f"{rel}.meta: expected a {want}")
    for meta in sorted(package.rglob("*.meta")):
        rel = meta.relative_to(package)
        if any(part.endswith("~") or part.startswith(".") for part in rel.parts):
            problem(f"{rel}: a .meta in a folder Unity ignores")
            continue
        asset = meta.with_name(meta.name[: -len(".meta")])
        if not asset.exists() and str(rel) != PLUGIN + ".meta":
            problem(f"{rel}: its asset does not exist")
        m = re.search(r"^guid: (\S+)$", meta.read_text(), re.M)
        if not m or not re.fullmatch(r"[0-9a-f]{32}", m.group(1)):
            problem(f"{rel}: no guid of 32 lowercase hex digits")
            continue
        if m.group(1) in guids:
            problem(f"{rel}: guid {m.group(1)} is also {guids[m.group(1)].relative_to(package)}'s")
        guids[m.group(1)] = meta

    # the native plugin
    plugin_meta = package / (PLUGIN + ".meta")
    if not plugin_meta.exists():
        problem(f"{PLUGIN}.meta is missing")
    else:
        platforms = plugin_platforms(plugin_meta.read_text())
        want = {
            "Editor: Editor": {"enabled": "1", "CPU": "x86_64", "OS": "Linux"},
            "Standalone: Linux64": {"enabled": "1", "CPU": "x86_64"},
        }
        for key, values in want.items():
            for name, value in values.items():
                got = platforms.get(key, {}).get(name)
                if got != value:
                    problem(f"{PLUGIN}.meta: {key} {name} is {got!r}, expected {value!r}")
        for key, values in platforms.items():
            if key not in want and values.get("enabled") != "0":
                problem(f"{PLUGIN}.meta: {key} is enabled (only the Linux editor and player are built)")
        excluded = platforms.get(": Any", {})
        for name in ("Exclude Editor", "Exclude Linux64"):
            if excluded.get(name) != "0":
                problem(f"{PLUGIN}.meta: {name} is {excluded.get(name)!r}, expected '0'")

    for p in problems:
        print(f"check_layout: {p}", file=sys.stderr)
    if problems:
        return 1
    n_meta = len(guids)
    print(f"package {manifest.get('name')} {manifest.get('version')}: {n_meta} .meta files, unique GUIDs, "
          f"{len(asmdefs)} asmdefs, plugin for the Linux x86_64 editor and player")
    return 0


if __name__ == "__main__":
    sys.exit(main())
