"""The Unity package files an export writes beside the data: runtime, shaders, prefab, manifests, and their ``.meta`` files."""

from __future__ import annotations

import hashlib
import importlib.resources
from pathlib import Path

from simulator.export.unity.binary import DATA_FILE, MAGIC, ROT_FILE

__all__ = ["ASSET_FILES", "CS_FILES", "asset_bytes", "data_guid", "guid", "is_ours", "meta_files"]

#: The C# runtime (core, no UnityEngine) and the optional MonoBehaviour.
CS_FILES: tuple[str, ...] = ("VimsimEpof.cs", "VimsimEpofBehaviour.cs", "VimsimEpofAsset.cs")
#: Every package file copied from ``simulator/export/unity/`` (paths relative to the export
#: folder, which is a UPM package: ``package.json`` at its root).
ASSET_FILES: tuple[str, ...] = (
    *CS_FILES,
    "VimsimOverlay.hlsl",
    "VimsimOverlay.shader",
    "VimsimOverlay.mat",
    "VimsimOverlay.prefab",
    "package.json",
    "Vimsim.Runtime.asmdef",
    "Editor/Vimsim.Editor.asmdef",
    "Editor/VimsimEpofImporter.cs",
    "SAMPLE.md",
)
_DATA_FILES = (DATA_FILE, ROT_FILE)
_MARK = b"vimsim export"  # in the first 4 KB of every text file vimsim writes

_COMMON = "  externalObjects: {}\n  userData: \n  assetBundleName: \n  assetBundleVariant: \n"
_IMPORTERS = {
    ".cs": "MonoImporter:\n  externalObjects: {}\n  serializedVersion: 2\n  defaultReferences: []\n"
    "  executionOrder: 0\n  icon: {instanceID: 0}\n  userData: \n  assetBundleName: \n  assetBundleVariant: \n",
    ".shader": "ShaderImporter:\n  externalObjects: {}\n  defaultTextures: []\n  nonModifiableTextures: []\n"
    "  userData: \n  assetBundleName: \n  assetBundleVariant: \n",
    ".hlsl": "ShaderIncludeImporter:\n" + _COMMON,
    ".mat": "NativeFormatImporter:\n  externalObjects: {}\n  mainObjectFileID: 2100000\n"
    "  userData: \n  assetBundleName: \n  assetBundleVariant: \n",
    ".prefab": "PrefabImporter:\n" + _COMMON,
    ".json": "PackageManifestImporter:\n" + _COMMON,
    ".asmdef": "AssemblyDefinitionImporter:\n" + _COMMON,
    ".md": "TextScriptImporter:\n" + _COMMON,
}


def guid(rel: str) -> str:
    """The fixed Unity GUID of a package file (the prefab and material refer to them)."""
    return hashlib.md5(f"vimsim-unity:{rel}".encode()).hexdigest()


def _substitute(text: str) -> str:
    """``{{guid:REL}}`` placeholders of the prefab and material -> the GUIDs of :func:`guid`."""
    out, pos = [], 0
    while (i := text.find("{{guid:", pos)) >= 0:
        j = text.index("}}", i)
        out += [text[pos:i], guid(text[i + 7 : j])]
        pos = j + 2
    return "".join(out) + text[pos:]


def asset_bytes(rel: str) -> bytes:
    """Contents of a package file as written (placeholders substituted)."""
    src = importlib.resources.files("simulator.export.unity")
    for part in rel.split("/"):
        src = src.joinpath(part)
    raw = src.read_bytes()
    return _substitute(raw.decode()).encode() if b"{{guid:" in raw else raw


def data_guid(rel: str, video_key: str) -> str:
    """The GUID of a per-video data file (``vimsim_epof.bin``, ``vimsim_epof_rot.bin``):
    from the video's content hash, so the data of two videos never share one (two exports
    import into one project) and a re-export of the same video keeps it (references to it
    in scenes survive)."""
    return hashlib.md5(f"vimsim-unity-data:{video_key}:{rel}".encode()).hexdigest()


def _meta(rel: str, video_key: str) -> bytes:
    if rel in _DATA_FILES:  # imported by Editor/VimsimEpofImporter.cs
        body = ("ScriptedImporter:\n  internalIDToNameTable: []\n  externalObjects: {}\n"
                "  serializedVersion: 2\n  userData: \n  assetBundleName: \n  assetBundleVariant: \n"
                f"  script: {{fileID: 11500000, guid: {guid('Editor/VimsimEpofImporter.cs')}, type: 3}}\n")  # fmt: skip
        return f"fileFormatVersion: 2\nguid: {data_guid(rel, video_key)}\n{body}".encode()
    if "." not in rel.rsplit("/", 1)[-1]:  # a folder
        body = "folderAsset: yes\nDefaultImporter:\n" + _COMMON
    else:
        body = _IMPORTERS.get(Path(rel).suffix, "DefaultImporter:\n" + _COMMON)
    return f"fileFormatVersion: 2\nguid: {guid(rel)}\n{body}".encode()


def meta_files(video_key: str = "", rot: bool = False) -> dict[str, bytes]:
    """``REL.meta`` -> contents for every package file, the ``Editor`` folder (fixed GUIDs:
    the runtime package is the same in every export) and the data files (``rot``: also
    :data:`ROT_FILE`; GUIDs from ``video_key``, the video's content hash: :func:`data_guid`)."""
    rels = (DATA_FILE, *([ROT_FILE] if rot else []), *ASSET_FILES, "Editor")
    return {f"{r}.meta": _meta(r, video_key) for r in rels}


def is_ours(path: Path) -> bool:
    """Whether an existing file was written by ``vimsim export`` (so it may be replaced)."""
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except OSError:
        return False
    if path.name in (DATA_FILE, ROT_FILE):
        return head.startswith(MAGIC)
    if path.name[:-5] in _DATA_FILES:  # a data file's: it selects vimsim's importer
        return path.suffix == ".meta" and guid("Editor/VimsimEpofImporter.cs").encode() in head
    if path.suffix == ".meta":  # ours: it holds the GUID vimsim gives that file
        return f"guid: {guid(path.name[:-5])}".encode() in head or any(
            f"guid: {guid(r)}".encode() in head for r in (*ASSET_FILES, DATA_FILE, "Editor")
        )
    ours = (guid(r).encode() for r in (*ASSET_FILES, DATA_FILE, "Editor"))
    return _MARK in head or b'"name": "Vimsim.' in head or any(g in head for g in ours)
