// vimsim export: VimsimEpofBehaviour.cs, an optional thin Unity MonoBehaviour around VimsimEpof.cs.
// Needs UnityEngine (and UnityEngine.Video for a VideoPlayer's time); VimsimEpof.cs does not.
// Every frame: the head's rotation -> vimsim yaw/pitch/roll -> EPOF at the video's time ->
// GRF opacity (eased with the exported rule: smoothing, ease-in, ease-out, when `ease` is on). docs/unity.md.
using UnityEngine;
using UnityEngine.Video;

namespace Vimsim
{
    public class VimsimEpofBehaviour : MonoBehaviour
    {
        [Tooltip("Export folder under StreamingAssets (holding vimsim_epof.bin); desktop and standalone builds")]
        public string streamingAssetsFolder = "vimsim";

        [Tooltip("Or the export itself: vimsim_epof.bin renamed to vimsim_epof.bytes (any platform, e.g. Android)")]
        public TextAsset exportAsset;

        [Tooltip("The head: the XR camera's transform (default Camera.main)")]
        public Transform head;

        [Tooltip("Time source: the VideoPlayer showing the 360 video (default: seconds since Start)")]
        public VideoPlayer video;

        [Tooltip("vimsim yaw (deg) of Unity's +z: 0 when +z shows the centre of the equirect frame; "
                 + "Unity's Skybox/Panoramic shader: its Rotation minus 90")]
        public float yawOffsetDeg = 0f;

        [Tooltip("Ease the opacity with the exported rule (vimsim epof --opacity-rule, --smooth, --ease-in, --ease-out)")]
        public bool ease = true;

        [Tooltip("Optional: material whose float property receives the opacity")]
        public Material grfMaterial;
        public string opacityProperty = "_Opacity";

        /// <summary>EPOF of the current frame, deg/s.</summary>
        public float Epof { get; private set; }
        /// <summary>GRF opacity of the current frame, 0..1.</summary>
        public float Opacity { get; private set; }
        public VimsimEpof Runtime { get; private set; }

        OpacityEasing easing;
        float startTime;

        void Awake()
        {
            try
            {
                Runtime = exportAsset != null
                    ? VimsimEpof.FromBytes(exportAsset.bytes, exportAsset.name)
                    : VimsimEpof.Load(System.IO.Path.Combine(Application.streamingAssetsPath, streamingAssetsFolder));
            }
            catch (VimsimLoadException e)
            {
                Debug.LogError("vimsim: " + e.Message);
                enabled = false;
                return;
            }
            easing = Runtime.CreateEasing();
            if (head == null && Camera.main != null) head = Camera.main.transform;
        }

        void Start()
        {
            startTime = Time.time;
        }

        void Update()
        {
            if (Runtime == null || head == null) return;
            double t = video != null ? video.time : (double)(Time.time - startTime);
            // Unity's eulerAngles (x down, y right, z left ear down; applied z, x, y about fixed
            // axes) -> vimsim (pitch up, yaw right, roll right ear down; yaw, pitch, roll intrinsic).
            Vector3 e = head.rotation.eulerAngles;
            float yaw, pitch, roll;
            VimsimEpof.FromUnityEuler(e.x, e.y, e.z, yawOffsetDeg, out yaw, out pitch, out roll);
            Epof = Runtime.Epof(t, yaw, pitch, roll);
            float op = Runtime.Opacity(Epof);
            Opacity = ease ? easing.Update(op, Time.deltaTime) : op;
            if (grfMaterial != null) grfMaterial.SetFloat(opacityProperty, Opacity);
        }
    }
}
