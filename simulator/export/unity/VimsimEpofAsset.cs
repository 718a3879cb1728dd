// vimsim export: VimsimEpofAsset.cs, a vimsim export imported into the project (Editor/VimsimEpofImporter.cs).
using UnityEngine;

namespace Vimsim
{
    /// <summary>The bytes of vimsim_epof.bin inside the build (any platform); load with
    /// VimsimEpof.FromBytes(asset.bytes, asset.sourceName) or VimsimEpof.LoadAsync.</summary>
    public class VimsimEpofAsset : ScriptableObject
    {
        [HideInInspector] public byte[] bytes;
        public string sourceName;
        [Tooltip("What the importer read from the header")]
        public string summary;
    }
}
