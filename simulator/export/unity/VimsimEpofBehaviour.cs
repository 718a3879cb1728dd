// vimsim export: VimsimEpofBehaviour.cs, the Unity MonoBehaviour around VimsimEpof.cs: the video
// player's frame + the head's rotation -> EPOF -> GRF opacity eased once per video frame (as
// `vimsim epof`) -> the overlay material (VimsimOverlay.shader: grains, vignette). docs/unity.md.
//
// Clock: the VideoPlayer's frame (VideoPlayer.frame: the index of the video frame on screen,
// counted in the video stream from its first frame, as vimsim counts; a stream that starts after
// its container or after the audio changes nothing). When the player's frame rate differs from
// the export's by more than 0.1 %, the frame is mapped through its time: floor(frame / playerFps
// * fps + 1e-6). The easing steps once per new video frame (VimsimPlaybackClock), holds while the
// player is paused, not prepared or showing no frame yet (frame < 0), and restarts on a seek and
// at the loop point. Without a VideoPlayer: seconds since Start, frame floor(t * fps + 1e-6).
// Outside the exported range: Epof, RawOpacity and EasedOpacity are NaN, the overlay draws
// nothing, and one warning is logged.
using System.Threading.Tasks;
using UnityEngine;
using UnityEngine.Video;

namespace Vimsim
{
    public class VimsimEpofBehaviour : MonoBehaviour
    {
        [Tooltip("The export imported into the project (vimsim_epof.bin, VimsimEpofImporter): any platform")]
        public VimsimEpofAsset epofAsset;

        [Tooltip("Or vimsim_epof.bin renamed *.bytes (a TextAsset)")]
        public TextAsset exportAsset;

        [Tooltip("Or an export folder under StreamingAssets (holding vimsim_epof.bin): desktop builds")]
        public string streamingAssetsFolder = "vimsim";

        [Tooltip("The head: the XR camera's transform (default Camera.main)")]
        public Transform head;

        [Tooltip("The VideoPlayer showing the 360 video (its frame is the clock; default: seconds since Start)")]
        public VideoPlayer video;

        [Tooltip("vimsim yaw (deg) of Unity's +z: 0 when +z shows the centre of the equirect frame; "
                 + "Unity's Skybox/Panoramic shader: its Rotation minus 90")]
        public float yawOffsetDeg = 0f;

        [Tooltip("Turn the head by the file's initial orientation (its spherical metadata), as vimsim does: "
                 + "on only when the app turns the video sphere by it; Unity's Skybox/Panoramic shows the frame as stored")]
        public bool applyOrientation = false;

        [Tooltip("Ease the opacity with the exported rule, once per video frame (vimsim epof's opacity column)")]
        public bool ease = true;

        [Tooltip("The overlay's renderer (VimsimOverlay.prefab's sphere with VimsimOverlay.mat); kept at the head")]
        public Renderer overlay;

        [Tooltip("Grain mask width in texels (0: as vimsim render, from the camera's pixel size)")]
        public int maskWidth = 0;

        [Tooltip("Optional: another material whose float property receives the drawn opacity")]
        public Material grfMaterial;
        public string opacityProperty = "_Opacity";

        /// <summary>EPOF of the current video frame, deg/s (NaN outside the export or before it loads).</summary>
        public float Epof { get { return clock == null ? float.NaN : clock.Epof; } }
        /// <summary>Un-eased GRF opacity (the exported rule before easing), 0..1.</summary>
        public float RawOpacity { get { return clock == null ? float.NaN : clock.RawOpacity; } }
        /// <summary>Opacity eased once per video frame with the exported rule (= vimsim epof's column), 0..1.</summary>
        public float EasedOpacity { get { return clock == null ? float.NaN : clock.EasedOpacity; } }
        /// <summary>What is drawn: EasedOpacity (or RawOpacity when ease is off); 0 outside the export.</summary>
        public float DrawnOpacity { get; private set; }
        /// <summary>The loaded runtime (null until the asynchronous load completes).</summary>
        public VimsimEpof Runtime { get; private set; }
        public VimsimPlaybackClock Clock { get { return clock; } }

        Task<VimsimEpof> loading;
        Task<byte[]> masking;
        int maskW;
        double pixelAngle, tanV, tanH;
        VimsimPlaybackClock clock;
        Material overlayMaterial;
        Texture2D mask;
        float startTime;
        bool warnedRange, warnedRate;

        void Awake()
        {
            if (head == null && Camera.main != null) head = Camera.main.transform;
            // The camera's pixel size and view (main thread), for the mask width and the vignette.
            var cam = head != null ? head.GetComponent<Camera>() : Camera.main;
            if (cam == null) cam = Camera.main;
            float vfov = cam != null ? cam.fieldOfView : 90f, aspect = cam != null ? cam.aspect : 1f;
            int pixels = cam != null ? cam.pixelHeight : 1440;
            tanV = System.Math.Tan(vfov * System.Math.PI / 360.0);
            tanH = tanV * aspect;
            pixelAngle = 2.0 * tanV / System.Math.Max(1, pixels);
            maskW = maskWidth > 0 ? maskWidth + (maskWidth % 2) : VimsimGrainMask.WidthFor(pixelAngle, SystemInfo.maxTextureSize);
            // Loaded, and the grain mask built, on a worker thread (the paper-mode table takes
            // ~0.3-0.8 s, a 4096-wide mask ~1 s): the main thread goes on.
            if (epofAsset != null) loading = VimsimEpof.FromBytesAsync(epofAsset.bytes, epofAsset.sourceName);
            else if (exportAsset != null) loading = VimsimEpof.FromBytesAsync(exportAsset.bytes, exportAsset.name);
            else loading = VimsimEpof.LoadAsync(System.IO.Path.Combine(Application.streamingAssetsPath, streamingAssetsFolder));
            int w = maskW;
            masking = loading.ContinueWith(t => Grains(t.Result.MitigationKind) ? VimsimGrainMask.Build(t.Result, w) : null,
                                           TaskContinuationOptions.OnlyOnRanToCompletion);
            if (video != null)
            {
                video.seekCompleted += OnRestart;
                video.loopPointReached += OnRestart;
            }
        }

        void OnDestroy()
        {
            if (video != null)
            {
                video.seekCompleted -= OnRestart;
                video.loopPointReached -= OnRestart;
            }
            if (mask != null) Destroy(mask);
        }

        void OnRestart(VideoPlayer source)
        {
            if (clock != null) clock.Reset();
        }

        void Start()
        {
            startTime = Time.time;
        }

        static bool Grains(string kind) { return kind == "grf" || kind == "grf+vignette"; }

        bool Ready()
        {
            if (Runtime != null) return true;
            if (loading == null || !loading.IsCompleted) return false;
            if (!loading.IsFaulted && !masking.IsCompleted) return false;
            if (loading.IsFaulted)
            {
                var ex = loading.Exception.GetBaseException();
                Debug.LogError("vimsim: " + ex.Message);
                loading = null;
                enabled = false;
                return false;
            }
            if (masking.IsFaulted || masking.IsCanceled)
            {
                Debug.LogError("vimsim: the grain mask could not be built (" + (masking.Exception != null ? masking.Exception.GetBaseException().Message : "canceled") + ")");
                loading = null;
                enabled = false;
                return false;
            }
            Runtime = loading.Result;
            Runtime.ApplyOrientation = applyOrientation; // the camera's angles are in the shown frame
            clock = Runtime.CreatePlaybackClock();
            SetUpOverlay(masking.Result);
            return true;
        }

        /// <summary>The video frame on screen in the export's numbering; false: hold (no new frame).</summary>
        bool VideoFrame(out long frame)
        {
            frame = -1;
            if (video == null)
            {
                frame = (long)System.Math.Floor((Time.time - startTime) * Runtime.Fps + VimsimEpof.FrameEps);
                return true;
            }
            if (!video.isPrepared || video.frame < 0) return false;
            double rate = video.frameRate;
            if (rate > 0 && System.Math.Abs(rate - Runtime.Fps) > 1e-3 * Runtime.Fps)
            {
                if (!warnedRate) Debug.LogWarning("vimsim: the VideoPlayer plays at " + rate + " fps, the export has " + Runtime.Fps + " fps; frames are mapped through their time");
                warnedRate = true;
                frame = (long)System.Math.Floor(video.frame / rate * Runtime.Fps + VimsimEpof.FrameEps);
            }
            else frame = video.frame;
            return true;
        }

        void Update()
        {
            if (!Ready() || head == null) return;
            long frame;
            if (VideoFrame(out frame))
            {   // the same frame (paused, or rendering faster than the video) holds in the clock
                Vector3 e = head.rotation.eulerAngles;
                float yaw, pitch, roll;
                VimsimEpof.FromUnityEuler(e.x, e.y, e.z, yawOffsetDeg, out yaw, out pitch, out roll);
                if (!clock.Advance(frame, yaw, pitch, roll) && !warnedRange)
                {
                    Debug.LogWarning("vimsim: video frame " + frame + " is outside the export (frames " + Runtime.RangeStartFrame
                        + ".." + (Runtime.RangeEndFrame - 1) + " of " + Runtime.SourceFrameCount + "); EPOF is NaN and the overlay is off there. "
                        + "Export the whole video (vimsim preprocess without --start/--end) to cover it");
                    warnedRange = true;
                }
            }
            float op = ease ? clock.EasedOpacity : clock.RawOpacity;
            DrawnOpacity = float.IsNaN(op) ? 0f : op;
            if (grfMaterial != null) grfMaterial.SetFloat(opacityProperty, DrawnOpacity);
        }

        void LateUpdate()
        {
            if (overlayMaterial == null || head == null) return;
            overlay.transform.position = head.position; // the sphere stays round the head
            overlayMaterial.SetVector("_VimsimHeadRight", head.right);
            overlayMaterial.SetVector("_VimsimHeadUp", head.up);
            overlayMaterial.SetVector("_VimsimHeadForward", head.forward);
            Vector4 c = overlayMaterial.GetVector("_VimsimCutout");
            c.w = DrawnOpacity;
            overlayMaterial.SetVector("_VimsimCutout", c);
        }

        void SetUpOverlay(byte[] maskBytes)
        {
            if (overlay == null) return;
            overlayMaterial = overlay.material; // this renderer's own instance
            string kind = Runtime.MitigationKind;
            bool grains = Grains(kind), vignette = kind == "vignette" || kind == "grf+vignette";
            int w = maskW;
            bool mips = VimsimGrainMask.UsesMips(pixelAngle, Runtime.CutoutInnerDeg, w / 2);
            if (grains)
            {
                mask = new Texture2D(w, w / 2, TextureFormat.R8, mips, true);
                mask.wrapModeU = TextureWrapMode.Repeat;
                mask.wrapModeV = TextureWrapMode.Clamp;
                mask.filterMode = mips ? FilterMode.Trilinear : FilterMode.Bilinear;
                mask.LoadRawTextureData(maskBytes);
                mask.Apply(mips, true); // mip levels box-filtered, as glGenerateMipmap in vimsim render
                overlayMaterial.SetTexture("_VimsimGrainMask", mask);
            }
            double th = tanH, tv = tanV;
            double rad = System.Math.PI / 180.0;
            overlayMaterial.SetVector("_VimsimCutout", new Vector4((float)(Runtime.CutoutInnerDeg * rad), (float)(Runtime.CutoutOuterDeg * rad), grains ? 1f : 0f, 0f));
            float rFull = (float)System.Math.Atan(System.Math.Sqrt(th * th + tv * tv)); // the view's corner
            overlayMaterial.SetVector("_VimsimVignette", new Vector4(rFull, (float)(Runtime.VignetteApertureMinDeg * rad / 2.0),
                (float)(Runtime.VignetteFeatherDeg * rad), vignette ? 1f : 0f));
            var col = Runtime.VignetteColor;
            overlayMaterial.SetVector("_VimsimVignetteColor", new Vector4(col[0], col[1], col[2], 1f));
            overlayMaterial.SetVector("_VimsimMask", new Vector4(w / 2, mips ? 1f : 0f, (float)(yawOffsetDeg * rad), 0f));
        }
    }
}
