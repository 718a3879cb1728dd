// vimsim export: Editor/VimsimEpofImporter.cs, imports vimsim_epof.bin as a VimsimEpofAsset.
// The export's vimsim_epof.bin.meta selects this importer for that file (an override importer for
// .bin: other .bin files keep theirs); a file renamed *.vimsimepof is imported by it too. The
// asset holds the bytes, so the export ships inside the build on every platform (Android, WebGL:
// no StreamingAssets file reads); drag it onto VimsimEpofBehaviour's epofAsset. The header is
// checked at import: a bad or older export is an import error naming the file and the fix.
using UnityEngine;
#if UNITY_2020_2_OR_NEWER
using UnityEditor.AssetImporters;
#else
using UnityEditor.Experimental.AssetImporters;
#endif

namespace Vimsim.Editor
{
#if UNITY_2020_2_OR_NEWER
    [ScriptedImporter(1, new[] { "vimsimepof" }, new[] { "bin" })]
#else
    [ScriptedImporter(1, "vimsimepof")]
#endif
    public class VimsimEpofImporter : ScriptedImporter
    {
        public override void OnImportAsset(AssetImportContext ctx)
        {
            byte[] bytes = System.IO.File.ReadAllBytes(ctx.assetPath);
            var asset = ScriptableObject.CreateInstance<VimsimEpofAsset>();
            asset.bytes = bytes;
            asset.sourceName = ctx.assetPath;
            try
            {
                var e = VimsimEpof.FromBytes(bytes, ctx.assetPath);
                asset.summary = e.Mode + " mode, " + e.FrameCount + " frames at " + e.Fps + " fps, "
                    + e.GrainCount + " grains, " + e.MitigationKind;
            }
            catch (VimsimLoadException ex)
            {
                ctx.LogImportError("vimsim: " + ex.Message);
                asset.summary = "not loadable: " + ex.Problem;
            }
            ctx.AddObjectToAsset("vimsim_epof", asset);
            ctx.SetMainObject(asset);
        }
    }
}
