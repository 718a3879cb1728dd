// vimsim export: VimsimEpof.cs, the EPOF runtime for engines (binary format version 4).
// Written by `vimsim export GRID.npz -o DIR --format unity`; docs/unity.md in vimsim.
// Plain C# (C# 6, .NET Framework 4.x / .NET Standard 2.0 profile): no UnityEngine here.
//
//   var e = Vimsim.VimsimEpof.Load(dir);              // reads DIR/vimsim_epof.bin (or LoadAsync)
//   if (e.Covers(videoTimeS)) { ... }                 // the export has this time's frame
//   float epof = e.Epof(videoTimeS, yawDeg, pitchDeg, rollDeg);   // deg/s; NaN outside the range
//   float raw = e.RawOpacity(epof);                   // un-eased GRF opacity, 0..1 (rule: e.OpacityRule)
//   var clock = e.CreatePlaybackClock();              // then per rendered frame, with the player's frame:
//   clock.Advance(videoFrame, yawDeg, pitchDeg, rollDeg);  // clock.EasedOpacity = vimsim epof's column
//
// Conventions, exactly as `vimsim epof`: angles in degrees; yaw + turns right (toward +lon),
// pitch + looks up, roll + tilts the head right ear down, applied yaw, then pitch, then roll
// (intrinsic); yaw = pitch = roll = 0 looks at the centre of the equirect frame. A time is
// seconds from the video start; it shows video frame floor(time * fps + 1e-6) (a variable-rate
// video: the last of FrameTimesS at or before it); the export covers
// frames RangeStartFrame .. RangeEndFrame - 1 of a source of SourceFrameCount frames.
// Numbers: the same computation as vimsim (paper mode: simulator.epof.ViewportOverlaps, its
// overlap table built at load; sphere mode: simulator.sphere.ViewportQuery). The grain layout
// (GrainCenters) is vimsim's (simulator.mitigation.grf.GrainField) and VimsimGrainMask.Build
// draws it as vimsim's grf_mask.frag does. Not thread safe (caches): one instance per thread.
using System;
using System.Collections.Generic;
using System.Globalization;
using System.IO;
using System.Text;
using System.Threading.Tasks;

namespace Vimsim
{
    /// <summary>A vimsim export could not be loaded: FilePath names the file, Problem says why
    /// (for a bad header field, Field names it, e.g. "grf.density").</summary>
    public class VimsimLoadException : IOException
    {
        public string FilePath { get; private set; }
        public string Problem { get; private set; }
        public string Field { get; private set; }

        public VimsimLoadException(string path, string problem) : this(path, problem, null) { }

        public VimsimLoadException(string path, string problem, string field)
            : base(path + ": " + problem)
        {
            FilePath = path;
            Problem = problem;
            Field = field;
        }
    }

    /// <summary>EPOF (deg/s) and GRF opacity of a viewport at a video time, from a vimsim export.</summary>
    public sealed class VimsimEpof
    {
        /// <summary>The binary format version this runtime reads.</summary>
        public const int FormatVersion = 5;
        /// <summary>File name of the data inside an export folder.</summary>
        public const string DataFileName = "vimsim_epof.bin";
        /// <summary>Tolerance (frames) of the time-to-frame rule.</summary>
        public const double FrameEps = 1e-6;
        static readonly byte[] Magic = Encoding.ASCII.GetBytes("VIMSIMEP");
        const int PrefixBytes = 16;

        /// <summary>"paper" (overlap-weighted window POFs) or "sphere" (exact, from the field).</summary>
        public string Mode { get; private set; }
        public double Fps { get; private set; }
        /// <summary>Video frame number of the first row (0 unless the grid covers part of the video).</summary>
        public int StartFrame { get; private set; }
        public int FrameCount { get; private set; }
        /// <summary>Exported range: frames RangeStartFrame (inclusive) .. RangeEndFrame (exclusive), and in seconds.</summary>
        public int RangeStartFrame { get { return StartFrame; } }
        public int RangeEndFrame { get { return StartFrame + FrameCount; } }
        public double RangeStartS { get { return FrameTimesS != null ? FrameTimesS[0] : StartFrame / Fps; } }
        public double RangeEndS { get { return FrameTimesS != null ? rangeEndS : (StartFrame + FrameCount) / Fps; } }
        /// <summary>A variable-rate video's frame times (s, one per exported frame; null: frame = floor(t * fps + 1e-6)).</summary>
        public double[] FrameTimesS { get; private set; }
        double rangeEndS;
        /// <summary>The source video's frame count and duration (s); SourceLengthKnown false: the grid's end.</summary>
        public int SourceFrameCount { get; private set; }
        public double SourceDurationS { get; private set; }
        public bool SourceLengthKnown { get; private set; }
        /// <summary>The file's initial orientation (yaw, pitch, roll degrees, from its spherical
        /// metadata), or null: Epof turns head angles by it (ViewAngles), as vimsim does.</summary>
        public double[] OrientationDeg { get; private set; }
        double[] pose; // head -> video rotation of OrientationDeg (row-major), or null
        /// <summary>Whether Epof turns head angles by OrientationDeg (default true: head angles
        /// as in a vimsim head path, on the clock of a player that honours the metadata). False
        /// when the angles are already in the video's frame: an app showing the frame as stored,
        /// e.g. Unity's Skybox/Panoramic (VimsimEpofBehaviour.applyOrientation).</summary>
        public bool ApplyOrientation { get; set; } = true;
        /// <summary>Viewport FOV in degrees (exact, horizontal and vertical).</summary>
        public double HfovDeg { get; private set; }
        public double VfovDeg { get; private set; }
        /// <summary>Opacity 0 at or below this EPOF (deg/s), 1 at or above OpacityHighDps.</summary>
        public double OpacityLowDps { get; private set; }
        public double OpacityHighDps { get; private set; }
        /// <summary>The opacity rule's name ("absolute", vimsim's default: fixed deg/s for every video;
        /// "paper" or "comfort": percentiles of this video's flow) and scale ("absolute" or "relative").</summary>
        public string OpacityRule { get; private set; }
        public string OpacityScale { get; private set; }
        /// <summary>Time constant (s) of the opacity's exponential smoothing; 0 = none (see CreateEasing).</summary>
        public double SmoothingS { get; private set; }
        /// <summary>Ease-in time (s): a full 0 -> 1 opacity change takes at least this long; 0 = no limit.</summary>
        public double EaseInS { get; private set; }
        /// <summary>Ease-out time (s): a full 1 -> 0 opacity change takes at least this long; 0 = no limit.</summary>
        public double EaseOutS { get; private set; }
        /// <summary>Content hash of the source video ("sha256:...", as in the grid file).</summary>
        public string SourceVideoHash { get; private set; }
        /// <summary>What the overlay draws: grf, vignette, grf+vignette or none (vimsim render --mitigation).</summary>
        public string MitigationKind { get; private set; }
        /// <summary>GRF: grain diameter (deg), blocked fraction, cutout radii (deg), seed of the layout.</summary>
        public double GrainDeg { get; private set; }
        public double GrainDensity { get; private set; }
        public double CutoutInnerDeg { get; private set; }
        public double CutoutOuterDeg { get; private set; }
        public int GrainSeed { get; private set; }
        public int GrainCount { get; private set; }
        /// <summary>Grain centres, world unit vectors (x right, y up, z forward), 3 floats per grain.</summary>
        public float[] GrainCenters { get; private set; }
        /// <summary>Vignette: aperture diameter at opacity 1 (deg), soft-edge width (deg), colour (rgb 0..1).</summary>
        public double VignetteApertureMinDeg { get; private set; }
        public double VignetteFeatherDeg { get; private set; }
        public float[] VignetteColor { get; private set; }
        /// <summary>The JSON header, verbatim.</summary>
        public string HeaderJson { get; private set; }
        public string SourcePath { get; private set; }

        float[] data;     // paper mode: FrameCount x rowLength, deg/s; sphere mode float32 field
        ushort[] half;    // sphere mode float16 field, as stored (half the memory of float32)
        double[] prefix;  // sphere mode: one frame's running sums per cell row, P[0..NLon] (P[0] = 0)
        int prefixRow = -1;
        int rowLength;
        PaperModel paper;
        SphereModel sphere;
        double[] coverPrefix; // sphere mode, a source not covering the sphere: covered cells' running sums
        /// <summary>A source that does not cover the sphere (VR180): below this share of the
        /// viewport covered, Epof fades to 0 (header coverage; 0 when it covers the sphere).</summary>
        public double MinCoverage { get; private set; }
        /// <summary>Whether the source's projection covers only part of the sphere (VR180): Epof is
        /// then the covered part's mean, as vimsim epof (docs/sources.md, Coverage).</summary>
        public bool PartialCoverage { get { return coverPrefix != null; } }
        double[] scratch;
        static readonly Dictionary<string, PaperModel> PaperCache = new Dictionary<string, PaperModel>();

        VimsimEpof() { }

        /// <summary>Load DIR/vimsim_epof.bin (or the .bin file itself). Throws VimsimLoadException.</summary>
        public static VimsimEpof Load(string dirOrFile)
        {
            return Load(dirOrFile, 0.0, 0.0);
        }

        /// <summary>Load with another viewport FOV (degrees, 0 = the exported one).</summary>
        public static VimsimEpof Load(string dirOrFile, double hfovDeg, double vfovDeg)
        {
            if (dirOrFile == null) throw new ArgumentNullException("dirOrFile");
            string path = Directory.Exists(dirOrFile) ? System.IO.Path.Combine(dirOrFile, DataFileName) : dirOrFile;
            byte[] bytes;
            try
            {
                bytes = File.ReadAllBytes(path);
            }
            catch (FileNotFoundException) { throw new VimsimLoadException(path, "file not found (expected the " + DataFileName + " written by vimsim export)"); }
            catch (DirectoryNotFoundException) { throw new VimsimLoadException(path, "file not found (its folder does not exist)"); }
            catch (UnauthorizedAccessException) { throw new VimsimLoadException(path, "file is not readable (permission denied)"); }
            catch (IOException ex) { throw new VimsimLoadException(path, "cannot read the file (" + ex.Message + ")"); }
            return FromBytes(bytes, path, hfovDeg, vfovDeg);
        }

        /// <summary>Load on a worker thread (the paper-mode table takes ~0.3-0.8 s): the calling
        /// (main) thread is not blocked; the task's exception is the VimsimLoadException.</summary>
        public static Task<VimsimEpof> LoadAsync(string dirOrFile)
        {
            return Task.Run(() => Load(dirOrFile, 0.0, 0.0));
        }

        /// <summary>FromBytes on a worker thread (e.g. a VimsimEpofAsset's bytes).</summary>
        public static Task<VimsimEpof> FromBytesAsync(byte[] bytes, string source)
        {
            return Task.Run(() => FromBytes(bytes, source, 0.0, 0.0));
        }

        /// <summary>Parse an export from memory (e.g. a Unity TextAsset's bytes); source names it in errors.</summary>
        public static VimsimEpof FromBytes(byte[] bytes, string source)
        {
            return FromBytes(bytes, source, 0.0, 0.0);
        }

        public static VimsimEpof FromBytes(byte[] bytes, string source, double hfovDeg, double vfovDeg)
        {
            if (bytes == null) throw new ArgumentNullException("bytes");
            source = source ?? "vimsim export";
            var e = new VimsimEpof();
            e.SourcePath = source;
            e.Parse(bytes, hfovDeg, vfovDeg);
            return e;
        }

        Header ParsePrefix(byte[] b, out long hlen)
        {
            string src = SourcePath;
            if (b.Length < PrefixBytes)
                throw new VimsimLoadException(src, "truncated: " + b.Length + " bytes, shorter than the 16-byte prefix; not a complete vimsim export");
            for (int i = 0; i < Magic.Length; i++)
                if (b[i] != Magic[i])
                    throw new VimsimLoadException(src, "not a vimsim export (no VIMSIMEP signature); make one with vimsim export GRID.npz -o DIR");
            int version = (int)ReadU32(b, 8);
            if (version < FormatVersion)
                throw new VimsimLoadException(src, "format version " + version + ", made by an older vimsim export (no grain layout, exported range, source length, variable-rate frame times, coverage or orientation); "
                    + "export again with vimsim export GRID.npz -o DIR --format unity and copy the new files (version " + FormatVersion + ")");
            if (version != FormatVersion)
                throw new VimsimLoadException(src, "header of format version " + version + "; this VimsimEpof.cs reads version " + FormatVersion + ": use the VimsimEpof.cs exported with the data");
            hlen = ReadU32(b, 12);
            if (PrefixBytes + hlen > b.Length)
                throw new VimsimLoadException(src, "truncated: the header needs " + (PrefixBytes + hlen) + " bytes, the file has " + b.Length);
            string json = Encoding.UTF8.GetString(b, PrefixBytes, (int)hlen);
            HeaderJson = json;
            Dictionary<string, object> h;
            try
            {
                h = MiniJson.Parse(json) as Dictionary<string, object>;
            }
            catch (FormatException ex) { throw new VimsimLoadException(src, "header is not valid JSON (" + ex.Message + ")"); }
            if (h == null) throw new VimsimLoadException(src, "header is not a JSON object");
            var hd = new Header(h, src);
            if (hd.Str("format") != "vimsim-epof")
                throw new VimsimLoadException(src, "header format is '" + hd.Str("format") + "', not vimsim-epof");
            if ((int)hd.Num("version") != FormatVersion)
                throw new VimsimLoadException(src, "header of format version " + hd.Num("version") + "; this VimsimEpof.cs reads version " + FormatVersion);
            return hd;
        }

        void ParseSettings(Header hd, double hfovOverride, double vfovOverride)
        {
            string src = SourcePath;
            Mode = hd.Str("mode");
            Fps = hd.Num("fps");
            StartFrame = (int)hd.Num("start_frame");
            FrameCount = (int)hd.Num("n_frames");
            if (!(Fps > 0) || FrameCount < 1)
                throw new VimsimLoadException(src, "header has fps " + Fps + " and " + FrameCount + " frames; expected fps > 0 and >= 1 frame");
            var rg = hd.Obj("range");
            if ((int)rg.Num("start_frame") != StartFrame || (int)rg.Num("end_frame") != StartFrame + FrameCount)
                throw new VimsimLoadException(src, "header field range: frames " + rg.Num("start_frame") + ".." + rg.Num("end_frame") + " do not match start_frame and n_frames", "range");
            FrameTimesS = null;
            if (hd.Has("frame_times_s"))
            {
                var ft = hd.DoubleArray("frame_times_s");
                rangeEndS = rg.Num("end_s");
                bool ok = ft.Length == FrameCount && rangeEndS > ft[ft.Length - 1];
                for (int i = 1; ok && i < ft.Length; i++) ok = ft[i] > ft[i - 1];
                if (!ok)
                    throw new VimsimLoadException(src, "header field frame_times_s: expected " + FrameCount + " increasing times before range.end_s", "frame_times_s");
                FrameTimesS = ft;
            }
            var so = hd.Obj("source");
            SourceFrameCount = (int)so.Num("n_frames");
            SourceDurationS = so.Num("duration_s");
            SourceLengthKnown = so.Num("known") != 0;
            if (so.Has("orientation_deg"))
            {
                var o = so.DoubleArray("orientation_deg");
                if (o.Length != 3 || double.IsNaN(o[0] + o[1] + o[2]) || double.IsInfinity(o[0] + o[1] + o[2]))
                    throw new VimsimLoadException(src, "header field source.orientation_deg: expected 3 finite degrees", "source.orientation_deg");
                OrientationDeg = o;
                pose = HeadRotation(Rad(o[0]), Rad(o[1]), Rad(o[2]));
            }
            if (SourceFrameCount < StartFrame + FrameCount)
                throw new VimsimLoadException(src, "header field source.n_frames: " + SourceFrameCount + " is shorter than the exported range's end " + (StartFrame + FrameCount), "source.n_frames");
            var vp = hd.Obj("viewport");
            HfovDeg = hfovOverride > 0 ? hfovOverride : vp.Num("hfov_deg");
            VfovDeg = vfovOverride > 0 ? vfovOverride : (hfovOverride > 0 ? hfovOverride : vp.Num("vfov_deg"));
            if (!(HfovDeg > 0 && HfovDeg < 180 && VfovDeg > 0 && VfovDeg < 180))
                throw new ArgumentOutOfRangeException("hfovDeg", "viewport FOV must be degrees in (0, 180); got " + HfovDeg + " x " + VfovDeg);
            var op = hd.Obj("opacity");
            OpacityLowDps = op.Num("low_dps");
            OpacityHighDps = op.Num("high_dps");
            OpacityRule = op.Has("name") ? op.Str("name") : "";
            OpacityScale = op.Has("scale") ? op.Str("scale") : "relative";
            SmoothingS = op.Num("smoothing_s");
            EaseInS = op.Num("ease_in_s");
            EaseOutS = op.Num("ease_out_s");
            if (!(SmoothingS >= 0 && EaseInS >= 0 && EaseOutS >= 0) || double.IsInfinity(SmoothingS + EaseInS + EaseOutS))
                throw new VimsimLoadException(src, "header opacity times (smoothing_s, ease_in_s, ease_out_s) must be seconds >= 0", "opacity");
            var video = hd.Obj("video");
            SourceVideoHash = video.Has("content_hash") ? video.Str("content_hash") : "";
        }

        void ParseMitigation(Header hd, byte[] b, long dataEnd)
        {
            string src = SourcePath;
            MitigationKind = hd.Str("mitigation");
            var g = hd.Obj("grf");
            GrainDeg = g.Num("grain_deg");
            GrainDensity = g.Num("density");
            CutoutInnerDeg = g.Num("inner_deg");
            CutoutOuterDeg = g.Num("outer_deg");
            GrainSeed = (int)g.Num("seed");
            GrainCount = (int)g.Num("n_grains");
            if (!(GrainDensity > 0 && GrainDensity < 1))
                throw new VimsimLoadException(src, "header field grf.density: " + GrainDensity + " is not a blocked fraction in (0, 1); export again", "grf.density");
            if (!(CutoutInnerDeg >= 0 && CutoutInnerDeg < CutoutOuterDeg && CutoutOuterDeg <= 180))
                throw new VimsimLoadException(src, "header fields grf.inner_deg, grf.outer_deg: cutout radii " + CutoutInnerDeg + ", " + CutoutOuterDeg
                    + " are not 0 <= inner < outer <= 180 degrees; export again", "grf.inner_deg");
            if (!(GrainDeg > 0 && GrainDeg <= 30))
                throw new VimsimLoadException(src, "header field grf.grain_deg: " + GrainDeg + " is not degrees in (0, 30]", "grf.grain_deg");
            var v = hd.Obj("vignette");
            VignetteApertureMinDeg = v.Num("aperture_min_deg");
            VignetteFeatherDeg = v.Num("feather_deg");
            var col = v.DoubleArray("color");
            if (!(VignetteApertureMinDeg > 0 && VignetteApertureMinDeg < 180) || !(VignetteFeatherDeg >= 0 && VignetteFeatherDeg <= 180) || col.Length != 3)
                throw new VimsimLoadException(src, "header field vignette: aperture_min_deg in (0, 180), feather_deg in [0, 180] and 3 colour values expected", "vignette");
            VignetteColor = new float[] { (float)col[0], (float)col[1], (float)col[2] };
            var gs = hd.Obj("grains");
            long off = (long)gs.Num("offset");
            var shape = gs.IntArray("shape");
            long bytes = b.Length - off;
            if (off < dataEnd || off > b.Length)
                throw new VimsimLoadException(src, "truncated: the data ends at " + dataEnd + " bytes, the grain layout starts at " + off + ", the file has " + b.Length);
            if (bytes % 12 != 0)
                throw new VimsimLoadException(src, "truncated: the grain layout needs " + (off + 12L * GrainCount) + " bytes, the file has " + b.Length);
            if (shape.Length != 2 || shape[0] != GrainCount || shape[1] != 3 || bytes != 12L * GrainCount)
                throw new VimsimLoadException(src, "header field grains: a layout of " + (bytes / 12) + " grains for grf.n_grains = " + GrainCount
                    + " (shape [" + string.Join(",", shape) + "]); export again", "grains");
            GrainCenters = new float[3 * GrainCount];
            Buffer.BlockCopy(b, (int)off, GrainCenters, 0, (int)bytes);
        }

        void Parse(byte[] b, double hfovOverride, double vfovOverride)
        {
            string src = SourcePath;
            long hlen;
            var hd = ParsePrefix(b, out hlen);
            ParseSettings(hd, hfovOverride, vfovOverride);
            var d = hd.Obj("data");
            string dtype = d.Str("dtype");
            int itemSize = dtype == "float16" ? 2 : dtype == "float32" ? 4 : 0;
            if (itemSize == 0) throw new VimsimLoadException(src, "data dtype '" + dtype + "'; expected float16 or float32", "data.dtype");
            var shape = d.IntArray("shape");
            if (shape.Length != 3 || shape[0] != FrameCount)
                throw new VimsimLoadException(src, "data shape [" + string.Join(",", shape) + "]; expected [n_frames, rows, columns]", "data.shape");
            long offset = (long)d.Num("offset");
            long count = (long)shape[0] * shape[1] * shape[2];
            long need = offset + count * itemSize;
            if (offset < PrefixBytes + hlen || need > b.Length)
                throw new VimsimLoadException(src, "truncated: the data needs " + need + " bytes, the file has " + b.Length);
            ParseMitigation(hd, b, need);
            rowLength = shape[1] * shape[2];
            if (!BitConverter.IsLittleEndian) throw new PlatformNotSupportedException("VimsimEpof reads little-endian data on little-endian machines only");
            if (Mode == "sphere" && itemSize == 2)
            {   // kept as stored: 2 bytes a cell; each frame's running sums are made when it is queried
                half = new ushort[count];
                Buffer.BlockCopy(b, (int)offset, half, 0, (int)(count * 2));
            }
            else
            {
                data = new float[count];
                if (itemSize == 4)
                    Buffer.BlockCopy(b, (int)offset, data, 0, (int)(count * 4));
                else
                    for (long i = 0; i < count; i++)
                        data[i] = HalfToFloat((ushort)(b[offset + 2 * i] | (b[offset + 2 * i + 1] << 8)));
            }
            if (Mode == "paper") SetUpPaper(hd, shape);
            else if (Mode == "sphere") SetUpSphere(hd, shape);
            else throw new VimsimLoadException(src, "mode '" + Mode + "'; expected paper or sphere", "mode");
        }

        void SetUpPaper(Header hd, int[] shape)
        {
            var g = hd.Obj("grid");
            var t = hd.Obj("overlap_table");
            double[] yawDeg = g.DoubleArray("yaw_deg"), pitchDeg = g.DoubleArray("pitch_deg");
            double[] num = { g.Num("yaw_step_deg"), g.Num("yaw_start_deg"), g.Num("hfov_deg"), g.Num("vfov_deg"),
                HfovDeg, VfovDeg, t.Num("pitch_step_deg"), t.Num("roll_step_deg"), t.Num("yaw_step_deg"),
                t.Num("rays"), t.Num("lat_step_deg"), t.Num("lon_step_deg") };
            var key = new StringBuilder();
            foreach (double x in yawDeg) key.Append(x.ToString("R", CultureInfo.InvariantCulture)).Append(',');
            key.Append('|');
            foreach (double x in pitchDeg) key.Append(x.ToString("R", CultureInfo.InvariantCulture)).Append(',');
            key.Append('|');
            foreach (double x in num) key.Append(x.ToString("R", CultureInfo.InvariantCulture)).Append(',');
            lock (PaperCache)
            {   // the table depends on the grid and FOV only: built once per process for all videos
                if (!PaperCache.TryGetValue(key.ToString(), out paper))
                {
                    paper = new PaperModel(yawDeg, pitchDeg, num[0], num[1], num[2], num[3], num[4], num[5],
                        num[6], num[7], num[8], (int)num[9], num[10], num[11]);
                    if (PaperCache.Count >= 4) PaperCache.Clear();
                    PaperCache[key.ToString()] = paper;
                }
            }
            scratch = new double[paper.P * paper.Y];
            if (shape[1] != paper.P || shape[2] != paper.Y)
                throw new VimsimLoadException(SourcePath, "data shape [" + string.Join(",", shape) + "] does not match the grid's " + paper.P + " x " + paper.Y + " windows", "data.shape");
        }

        void SetUpSphere(Header hd, int[] shape)
        {
            var f = hd.Obj("field");
            sphere = new SphereModel(f.Num("cell_deg"), f.Num("query_step_deg"), HfovDeg, VfovDeg, (int)f.Num("cache_bins"));
            if (shape[1] != sphere.NLat || shape[2] != sphere.NLon)
                throw new VimsimLoadException(SourcePath, "data shape [" + string.Join(",", shape) + "] does not match " + f.Num("cell_deg") + " deg cells (" + sphere.NLat + " x " + sphere.NLon + ")", "data.shape");
            prefix = new double[shape[1] * (shape[2] + 1)];
            if (hd.Has("coverage"))
            {   // a source that does not cover the sphere (VR180): the covered cells' running sums
                var cv = hd.Obj("coverage");
                var cells = cv.DoubleArray("cells");
                int nl = sphere.NLon;
                if (cells.Length != sphere.NLat * nl)
                    throw new VimsimLoadException(SourcePath, "header field coverage.cells: expected " + (sphere.NLat * nl) + " values", "coverage.cells");
                MinCoverage = cv.Num("min_coverage");
                coverPrefix = new double[sphere.NLat * (nl + 1)];
                for (int r = 0; r < sphere.NLat; r++)
                {
                    double acc = 0;
                    for (int j = 0; j < nl; j++) { acc += cells[r * nl + j]; coverPrefix[r * (nl + 1) + j + 1] = acc; }
                }
            }
        }

        /// <summary>Sphere mode: running sums along each cell row of one frame (double: exact to
        /// ~1e-12 relative; a run of interior cells costs two reads), made when the frame is first
        /// queried (the same sums as summing the whole field at load, one frame at a time).</summary>
        double[] FramePrefix(int row)
        {
            if (row == prefixRow) return prefix;
            int nl = sphere.NLon, rows = sphere.NLat;
            long src0 = (long)row * rows * nl;
            for (int r = 0; r < rows; r++)
            {
                double acc = 0;
                long s = src0 + (long)r * nl;
                int dst = r * (nl + 1);
                prefix[dst] = 0;
                if (half != null)
                    for (int j = 0; j < nl; j++) { acc += HalfToFloat(half[s + j]); prefix[dst + j + 1] = acc; }
                else
                    for (int j = 0; j < nl; j++) { acc += data[s + j]; prefix[dst + j + 1] = acc; }
            }
            prefixRow = row;
            return prefix;
        }

        /// <summary>Bytes the flow data holds in memory (sphere mode: the field as stored plus one
        /// frame's sums; paper mode: float32 windows), for the footprint table of docs/unity.md.</summary>
        public long DataBytes
        {
            get
            {
                long n = (half != null ? 2L * half.Length : 0) + (data != null ? 4L * data.Length : 0);
                return n + (prefix != null ? 8L * prefix.Length : 0);
            }
        }

        static uint ReadU32(byte[] b, int o)
        {
            return (uint)(b[o] | (b[o + 1] << 8) | (b[o + 2] << 16) | (b[o + 3] << 24));
        }

        static float[] halfTable;

        /// <summary>IEEE 754 binary16 -> float (exact).</summary>
        public static float HalfToFloat(ushort h)
        {
            if (halfTable == null)
            {
                var t = new float[65536];
                for (int i = 0; i < 65536; i++) t[i] = HalfToFloatSlow((ushort)i);
                halfTable = t;
            }
            return halfTable[h];
        }

        static float HalfToFloatSlow(ushort h)
        {
            int sign = (h >> 15) & 1, exp = (h >> 10) & 0x1f, man = h & 0x3ff;
            float v;
            if (exp == 0) v = man * (1.0f / 16777216.0f); // subnormal: man * 2^-24
            else if (exp == 31) v = man == 0 ? float.PositiveInfinity : float.NaN;
            else v = (float)((1024 + man) * Math.Pow(2.0, exp - 25));
            return sign == 1 ? -v : v;
        }

        // ------------------------------------------------------------------ queries
        /// <summary>Video frame shown at a time (s from the video start), clamped to the exported frames.</summary>
        public int FrameAt(double timeS)
        {
            if (double.IsNaN(timeS) || double.IsInfinity(timeS))
                throw new ArgumentOutOfRangeException("timeS", "time must be finite seconds; got " + timeS);
            double f = FrameOf(timeS);
            if (f < StartFrame) return StartFrame;
            if (f > StartFrame + FrameCount - 1) return StartFrame + FrameCount - 1;
            return (int)f;
        }

        /// <summary>Whether the export has the frame shown at a time (s from the video start):
        /// RangeStartFrame <= floor(t * fps + 1e-6) < RangeEndFrame; false for NaN or infinite.</summary>
        public bool Covers(double timeS)
        {
            if (double.IsNaN(timeS) || double.IsInfinity(timeS)) return false;
            return CoversFrame(FrameOf(timeS));
        }

        /// <summary>The video frame shown at a finite time (s): floor(t * fps + 1e-6), or for a
        /// variable-rate export the last of FrameTimesS at or before t (tolerance 1e-6 / fps s):
        /// StartFrame - 1 before the first, RangeEndFrame from RangeEndS on.</summary>
        public double FrameOf(double timeS)
        {
            if (FrameTimesS == null) return Math.Floor(timeS * Fps + FrameEps);
            double t = timeS + FrameEps / Fps;
            if (t >= rangeEndS) return StartFrame + FrameCount;
            int lo = 0, hi = FrameTimesS.Length; // first index with time > t
            while (lo < hi) { int mid = (lo + hi) / 2; if (FrameTimesS[mid] <= t) lo = mid + 1; else hi = mid; }
            return StartFrame + lo - 1;
        }

        /// <summary>Whether the export has a video frame.</summary>
        public bool CoversFrame(double frame)
        {
            return frame >= StartFrame && frame < StartFrame + FrameCount;
        }

        /// <summary>EPOF in deg/s of the viewport (degrees) at a video time (s), as vimsim epof;
        /// NaN where the export does not cover the time (Covers false; FrameAt clamps instead).</summary>
        public float Epof(double timeS, float yawDeg, float pitchDeg, float rollDeg)
        {
            if (!Covers(timeS)) return float.NaN;
            return (float)EpofAtFrame(FrameAt(timeS), yawDeg, pitchDeg, rollDeg);
        }

        /// <summary>EPOF in deg/s at a video frame number (StartFrame .. StartFrame + FrameCount - 1).</summary>
        public double EpofAtFrame(int frame, double yawDeg, double pitchDeg, double rollDeg)
        {
            int row = frame - StartFrame;
            if (row < 0 || row >= FrameCount)
                throw new ArgumentOutOfRangeException("frame", "frame " + frame + " outside " + StartFrame + ".." + (StartFrame + FrameCount - 1));
            if (double.IsNaN(yawDeg + pitchDeg + rollDeg) || double.IsInfinity(yawDeg + pitchDeg + rollDeg))
                throw new ArgumentOutOfRangeException("yawDeg", "orientation must be finite degrees");
            if (pose != null && ApplyOrientation)
            {
                double[] v = ViewAngles(yawDeg, pitchDeg, rollDeg);
                yawDeg = v[0]; pitchDeg = v[1]; rollDeg = v[2];
            }
            if (paper != null) return paper.Query(data, row * rowLength, yawDeg, pitchDeg, rollDeg, scratch);
            double e = sphere.Query(FramePrefix(row), 0, yawDeg, pitchDeg, rollDeg);
            if (coverPrefix == null) return e;
            // the covered part's mean, faded where the viewer sees mostly no content
            double share = Math.Max(0.0, Math.Min(1.0, sphere.Query(coverPrefix, 0, yawDeg, pitchDeg, rollDeg)));
            return share > 1e-9 ? e / share * Math.Min(1.0, share / MinCoverage) : 0.0;
        }

        /// <summary>Covered share (0..1) of the viewport at a head pose (turned by the initial
        /// orientation as Epof is): 1 for a source covering the sphere (vimsim epof's coverage column).</summary>
        public double Coverage(double yawDeg, double pitchDeg, double rollDeg)
        {
            if (coverPrefix == null) return 1.0;
            double[] v = ViewAngles(yawDeg, pitchDeg, rollDeg);
            return Math.Max(0.0, Math.Min(1.0, sphere.Query(coverPrefix, 0, v[0], v[1], v[2])));
        }

        /// <summary>(yaw, pitch, roll) degrees of the view in the video's frame for a head pose:
        /// the head's turned by the file's initial orientation, R(OrientationDeg) R(head)
        /// (simulator.media.spherical.view_angles_deg), else the head's. Epof applies it; draw
        /// the video and the overlay at these angles, as vimsim render does.</summary>
        public double[] ViewAngles(double yawDeg, double pitchDeg, double rollDeg)
        {
            if (pose == null || !ApplyOrientation) return new double[] { yawDeg, pitchDeg, rollDeg };
            double[] H = HeadRotation(Rad(yawDeg), Rad(pitchDeg), Rad(rollDeg)), M = new double[9];
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    M[3 * i + j] = pose[3 * i] * H[j] + pose[3 * i + 1] * H[3 + j] + pose[3 * i + 2] * H[6 + j];
            const double D = 180.0 / Math.PI;
            double pitch = Math.Asin(Math.Max(-1.0, Math.Min(1.0, M[5]))) * D;
            if (Math.Abs(M[5]) < 1 - 1e-12)
                return new double[] { Math.Atan2(M[2], M[8]) * D, pitch, Math.Atan2(-M[3], M[4]) * D };
            return new double[] { Math.Atan2(-M[6], M[0]) * D, pitch, 0.0 };
        }

        /// <summary>Un-eased GRF opacity (0..1) of an EPOF (deg/s): linear from OpacityLowDps to
        /// OpacityHighDps, clamped (the exported rule, OpacityRule, before easing); NaN for NaN.</summary>
        public float RawOpacity(float epofDps)
        {
            if (float.IsNaN(epofDps)) return float.NaN;
            double lo = OpacityLowDps, hi = OpacityHighDps, e = epofDps;
            if (hi > lo) return (float)Math.Min(1.0, Math.Max(0.0, (e - lo) / (hi - lo)));
            return e > lo ? 1f : 0f; // constant flow: a step at the threshold
        }

        /// <summary>Old name of RawOpacity (un-eased); the eased opacity is VimsimPlaybackClock.EasedOpacity.</summary>
        [Obsolete("Opacity is the un-eased opacity: use RawOpacity, or VimsimPlaybackClock.EasedOpacity for the eased one")]
        public float Opacity(float epofDps) { return RawOpacity(epofDps); }

        /// <summary>A stateful opacity easing with the exported rule (SmoothingS, EaseInS, EaseOutS;
        /// all 0 = passthrough): feed it RawOpacity(Epof(...)) once per video frame (Step) for
        /// vimsim epof's opacity column; CreatePlaybackClock does that from a player's frames.</summary>
        public OpacityEasing CreateEasing()
        {
            return new OpacityEasing(SmoothingS, Fps, EaseInS, EaseOutS);
        }

        /// <summary>A clock that steps the eased opacity once per video frame from a player's frame
        /// numbers (holds on a repeated frame, resets on a seek or loop).</summary>
        public VimsimPlaybackClock CreatePlaybackClock()
        {
            return new VimsimPlaybackClock(this);
        }

        /// <summary>Number of cached sphere-mode weight bins (0 in paper mode).</summary>
        public int CachedBins { get { return sphere == null ? 0 : sphere.CachedBins; } }

        /// <summary>Paper mode: the overlap table (n_pitch, n_roll, n_u + 1, P, Y), for checks.</summary>
        public float[] OverlapTable { get { return paper == null ? null : paper.Table; } }

        // --------------------------------------------------------- Unity conversion
        /// <summary>
        /// vimsim yaw/pitch/roll (degrees) of a Unity rotation given as Transform.eulerAngles (x, y, z).
        /// Unity applies z, then x, then y about fixed axes (= y, x, z intrinsic, vimsim's order),
        /// +x rotation looks down and +z rotation tilts the head left ear down; Unity's world has the
        /// same axes (+x right, +y up, +z forward). So yaw = y + yawOffsetDeg, pitch = -x, roll = -z,
        /// each wrapped to (-180, 180]. yawOffsetDeg = vimsim yaw of Unity's +z (the video's
        /// placement; docs/unity.md). Example: eulerAngles (350, 30, 5), offset 0 -> yaw 30, pitch 10, roll -5.
        /// </summary>
        public static void FromUnityEuler(float xDeg, float yDeg, float zDeg, float yawOffsetDeg,
                                          out float yawDeg, out float pitchDeg, out float rollDeg)
        {
            yawDeg = (float)Wrap180((double)yDeg + yawOffsetDeg);
            pitchDeg = (float)-Wrap180(xDeg);
            rollDeg = (float)-Wrap180(zDeg);
        }

        /// <summary>An angle in degrees wrapped to (-180, 180].</summary>
        public static double Wrap180(double a)
        {
            double r = PyMod(a + 180.0, 360.0) - 180.0; // [-180, 180)
            return r == -180.0 ? 180.0 : r;
        }

        /// <summary>Floating modulo with the sign of the divisor (numpy's np.mod / Python's %).</summary>
        internal static double PyMod(double a, double b)
        {
            double m = a % b; // C fmod
            if (m != 0.0 && ((b < 0) != (m < 0))) m += b;
            return m;
        }

        /// <summary>
        /// R = Ry(yaw) Rx(-pitch) Rz(-roll) (head -> world), row-major 3x3, radians in; computed
        /// as scipy's Rotation.from_euler("YXZ", [yaw, -pitch, -roll]).as_matrix() does
        /// (elementary quaternions, Hamilton products, quaternion -> matrix), so that the same
        /// inputs give the same bits where the tables need them.
        /// </summary>
        internal static double[] HeadRotation(double yaw, double pitch, double roll)
        {
            double[] q = Compose(Compose(Elementary(1, yaw), Elementary(0, -pitch)), Elementary(2, -roll));
            double x = q[0], y = q[1], z = q[2], w = q[3];
            double x2 = x * x, y2 = y * y, z2 = z * z, w2 = w * w;
            double xy = x * y, zw = z * w, xz = x * z, yw = y * w, yz = y * z, xw = x * w;
            return new double[] {
                x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw),
                2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw),
                2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2 };
        }

        static double[] Elementary(int axis, double angle)
        {
            var q = new double[] { 0.0, 0.0, 0.0, Math.Cos(angle / 2) };
            q[axis] = Math.Sin(angle / 2);
            return q;
        }

        static double[] Compose(double[] p, double[] q)
        {
            double cx = p[1] * q[2] - p[2] * q[1], cy = p[2] * q[0] - p[0] * q[2], cz = p[0] * q[1] - p[1] * q[0];
            return new double[] {
                p[3] * q[0] + q[3] * p[0] + cx,
                p[3] * q[1] + q[3] * p[1] + cy,
                p[3] * q[2] + q[3] * p[2] + cz,
                p[3] * q[3] - (p[0] * q[0] + p[1] * q[1] + p[2] * q[2]) };
        }

        /// <summary>Degrees to radians as Python's math.radians and numpy's deg2rad: x * (pi / 180).</summary>
        internal static double Rad(double deg) { return deg * (Math.PI / 180.0); }

        /// <summary>Round half to even (Python's round, numpy's rint).</summary>
        internal static long RoundEven(double x)
        {
            return (long)Math.Round(x, MidpointRounding.ToEven);
        }
    }

    /// <summary>
    /// The eased opacity of `vimsim epof`, stepped from a video player's frames (the clock of
    /// VimsimEpofBehaviour). Call Advance(frame, pose) once per rendered frame with the video frame
    /// the player shows: a new frame steps the easing once per video frame (frames skipped since
    /// the last call, up to MaxCatchUpFrames, are stepped too, with the current pose); the same
    /// frame holds everything (a paused player, a render rate above the video's); a frame before
    /// the last one or more than MaxCatchUpFrames after it is a seek or a loop: the easing restarts
    /// there, as a viewing that starts at that frame. Outside the exported range Epof, RawOpacity
    /// and EasedOpacity are NaN, OutOfRange is true and the easing restarts on re-entry.
    /// </summary>
    public sealed class VimsimPlaybackClock
    {
        readonly VimsimEpof e;
        readonly OpacityEasing easing;
        bool started;

        public VimsimPlaybackClock(VimsimEpof epof)
        {
            if (epof == null) throw new ArgumentNullException("epof");
            e = epof;
            easing = epof.CreateEasing();
            MaxCatchUpFrames = Math.Max(1, (int)Math.Ceiling(epof.Fps / 2.0));
            Reset();
        }

        /// <summary>The last video frame given to Advance (long.MinValue before the first).</summary>
        public long Frame { get; private set; }
        /// <summary>EPOF (deg/s), un-eased and eased opacity (0..1) of Frame; NaN outside the range.</summary>
        public float Epof { get; private set; }
        public float RawOpacity { get; private set; }
        public float EasedOpacity { get; private set; }
        /// <summary>The last frame was outside the exported range.</summary>
        public bool OutOfRange { get; private set; }
        /// <summary>Restarts of the easing after the first frame (seeks, loops, re-entries).</summary>
        public int Restarts { get; private set; }
        /// <summary>Largest forward jump (frames) stepped through frame by frame; larger: a seek.</summary>
        public int MaxCatchUpFrames { get; set; }

        /// <summary>Forget the history: the next Advance starts the easing (seek, loop, new video).</summary>
        public void Reset()
        {
            easing.Reset();
            started = false;
            Frame = long.MinValue;
            Epof = RawOpacity = EasedOpacity = float.NaN;
        }

        /// <summary>The frame the player shows, and the head pose (degrees); false outside the range.</summary>
        public bool Advance(long frame, float yawDeg, float pitchDeg, float rollDeg)
        {
            if (!e.CoversFrame(frame))
            {
                if (started) Restarts++;
                Reset();
                Frame = frame;
                OutOfRange = true;
                return false;
            }
            OutOfRange = false;
            if (started && frame == Frame) return true; // the same video frame: hold
            long from = frame;
            if (started && frame > Frame && frame - Frame <= MaxCatchUpFrames) from = Frame + 1;
            else
            {
                if (started) Restarts++;
                easing.Reset();
            }
            for (long f = from; f <= frame; f++)
            {
                double ep = e.EpofAtFrame((int)f, yawDeg, pitchDeg, rollDeg);
                Epof = (float)ep;
                RawOpacity = e.RawOpacity(Epof);
                EasedOpacity = easing.Step(RawOpacity);
            }
            Frame = frame;
            started = true;
            return true;
        }

        /// <summary>Advance with a time (s from the video start): frame FrameOf(t): floor(t * fps + 1e-6), or from FrameTimesS.</summary>
        public bool AdvanceTime(double timeS, float yawDeg, float pitchDeg, float rollDeg)
        {
            if (double.IsNaN(timeS) || double.IsInfinity(timeS)) return Advance(long.MinValue, yawDeg, pitchDeg, rollDeg);
            return Advance((long)e.FrameOf(timeS), yawDeg, pitchDeg, rollDeg);
        }
    }

    /// <summary>
    /// The grain coverage texture of the overlay (VimsimOverlay.hlsl's _VimsimGrainMask) from the
    /// exported layout, as vimsim's grf_mask.frag renders it: an equirect of width W and height W / 2,
    /// row 0 = north, column 0 at lon -180 deg; texel centre (x + 0.5, y + 0.5) is the direction
    /// p at lon (x + 0.5) / W 360 - 180, lat 90 - (y + 0.5) / H 180 deg; coverage = 1 - prod over
    /// grains (1 - clamp((chord - |p - c|) / (pi / H) + 1/2, 0, 1)), chord = 2 sin(radius / 2),
    /// radius = grain_deg / 2: the union of discs with edges box-filtered one texel row wide.
    /// </summary>
    public static class VimsimGrainMask
    {
        /// <summary>Mask width for an eye whose largest pixel spans pixelAngleRad, as vimsim render:
        /// texels no larger than a pixel, at least 512, at most min(8192, maxTextureSize), even.</summary>
        public static int WidthFor(double pixelAngleRad, int maxTextureSize)
        {
            int w = (int)Math.Ceiling(2.0 * Math.PI / pixelAngleRad);
            w = Math.Max(512, w + (w % 2));
            return Math.Min(w, Math.Min(8192, maxTextureSize));
        }

        /// <summary>Whether the mask needs mip levels (a pixel where grains show is larger than a
        /// texel row), as vimsim render: pixelAngle cos(inner - 1 deg) > 0.99 pi / H.</summary>
        public static bool UsesMips(double pixelAngleRad, double cutoutInnerDeg, int height)
        {
            double reach = VimsimEpof.Rad(Math.Max(cutoutInnerDeg - 1.0, 0.0));
            return pixelAngleRad * Math.Cos(reach) > 0.99 * Math.PI / height;
        }

        /// <summary>Coverage bytes (0..255, row 0 north), width x width / 2, of an export's grains.</summary>
        public static byte[] Build(VimsimEpof e, int width)
        {
            return Build(e.GrainCenters, e.GrainDeg, width);
        }

        /// <summary>Coverage bytes of grains (3 floats each, world unit vectors) of diameter grainDeg.</summary>
        public static byte[] Build(float[] centers, double grainDeg, int width)
        {
            if (width < 2 || width % 2 != 0) throw new ArgumentOutOfRangeException("width", "mask width must be even and >= 2");
            int W = width, H = width / 2, n = centers.Length / 3;
            double radius = VimsimEpof.Rad(grainDeg) / 2.0, fp = Math.PI / H;
            float chord = (float)(2.0 * Math.Sin(radius / 2.0));
            double reach = radius + fp;
            var rowSin = new double[H]; var rowCos = new double[H];
            for (int y = 0; y < H; y++) { double lat = Math.PI / 2 - (y + 0.5) * fp; rowSin[y] = Math.Sin(lat); rowCos[y] = Math.Cos(lat); }
            var colSin = new double[W]; var colCos = new double[W];
            for (int x = 0; x < W; x++) { double lon = (x + 0.5) / W * 2.0 * Math.PI - Math.PI; colSin[x] = Math.Sin(lon); colCos[x] = Math.Cos(lon); }
            const int Band = 32; // rows per pass: memory W x 32 floats, not W x H
            int nBands = (H + Band - 1) / Band;
            var lists = new List<int>[nBands];
            var y0s = new int[n]; var y1s = new int[n];
            for (int g = 0; g < n; g++)
            {
                double lat = Math.Asin(Math.Max(-1.0, Math.Min(1.0, (double)centers[3 * g + 1])));
                y0s[g] = Math.Max(0, (int)Math.Floor((Math.PI / 2 - (lat + reach)) / fp - 0.5));
                y1s[g] = Math.Min(H - 1, (int)Math.Ceiling((Math.PI / 2 - (lat - reach)) / fp - 0.5));
                for (int b = y0s[g] / Band; b <= y1s[g] / Band; b++) (lists[b] ?? (lists[b] = new List<int>())).Add(g);
            }
            var mask = new byte[(long)W * H];
            var trans = new float[Band * W];
            for (int b = 0; b < nBands; b++)
            {
                int yb = b * Band, ye = Math.Min(H, yb + Band);
                for (int i = 0; i < trans.Length; i++) trans[i] = 1f;
                if (lists[b] != null)
                    foreach (int g in lists[b])
                        Stamp(centers, g, Math.Max(yb, y0s[g]), Math.Min(ye - 1, y1s[g]), yb, W, reach, chord, (float)fp, rowSin, rowCos, colSin, colCos, trans);
                for (int y = yb; y < ye; y++)
                    for (int x = 0; x < W; x++)
                        mask[(long)y * W + x] = (byte)(int)((1f - trans[(y - yb) * W + x]) * 255f + 0.5f);
            }
            return mask;
        }

        static void Stamp(float[] c, int g, int y0, int y1, int yb, int W, double reach, float chord, float fp,
                          double[] rowSin, double[] rowCos, double[] colSin, double[] colCos, float[] trans)
        {
            float cx = c[3 * g], cy = c[3 * g + 1], cz = c[3 * g + 2];
            double lon = Math.Atan2(cx, cz);
            for (int y = y0; y <= y1; y++)
            {
                double cl = rowCos[y];
                int x0, count;
                if (cl <= Math.Sin(reach)) { x0 = 0; count = W; } // the cap reaches round the pole
                else
                {
                    double dlon = Math.Asin(Math.Sin(reach) / cl) + 2.0 * Math.PI / W;
                    x0 = (int)Math.Floor((lon - dlon + Math.PI) / (2.0 * Math.PI) * W - 0.5);
                    int x1 = (int)Math.Ceiling((lon + dlon + Math.PI) / (2.0 * Math.PI) * W - 0.5);
                    count = Math.Min(W, x1 - x0 + 1);
                }
                float sl = (float)rowSin[y], clf = (float)cl;
                int row = (y - yb) * W;
                for (int k = 0; k < count; k++)
                {
                    int x = ((x0 + k) % W + W) % W;
                    float px = clf * (float)colSin[x] - cx, py = sl - cy, pz = clf * (float)colCos[x] - cz;
                    float cov = (chord - (float)Math.Sqrt(px * px + py * py + pz * pz)) / fp + 0.5f;
                    if (cov <= 0f) continue;
                    trans[row + x] *= 1f - Math.Min(cov, 1f);
                }
            }
        }
    }

    /// <summary>
    /// The opacity easing of `vimsim epof` (simulator.mitigation.grf.OpacityRule), causal, starting at the
    /// first value: per video frame an exponential smoothing v += a (x - v), a = 1 - exp(-1 /
    /// (fps S)) (S = smoothing time constant, 0 = off), then a slew-rate limit on the eased
    /// value e: it rises by at most 1 / (fps easeIn) and falls by at most 1 / (fps easeOut) per
    /// frame (0 = no limit). Step() advances one video frame; Update() advances any time step
    /// dt (render frames: a = 1 - exp(-dt / S), limits dt / easeIn, dt / easeOut).
    /// </summary>
    public sealed class OpacityEasing
    {
        readonly double tau, aFrame, easeIn, easeOut, upFrame, downFrame;
        double smooth, value;
        bool started;

        /// <summary>Exponential smoothing only (time constant S seconds, 0 = passthrough).</summary>
        public OpacityEasing(double timeConstantS, double fps) : this(timeConstantS, fps, 0.0, 0.0) { }

        public OpacityEasing(double timeConstantS, double fps, double easeInS, double easeOutS)
        {
            if (!(timeConstantS >= 0) || double.IsInfinity(timeConstantS))
                throw new ArgumentOutOfRangeException("timeConstantS", "time constant must be seconds >= 0");
            if (!(easeInS >= 0) || double.IsInfinity(easeInS))
                throw new ArgumentOutOfRangeException("easeInS", "ease-in time must be seconds >= 0");
            if (!(easeOutS >= 0) || double.IsInfinity(easeOutS))
                throw new ArgumentOutOfRangeException("easeOutS", "ease-out time must be seconds >= 0");
            if (!(fps > 0)) throw new ArgumentOutOfRangeException("fps", "fps must be > 0");
            tau = timeConstantS;
            easeIn = easeInS;
            easeOut = easeOutS;
            aFrame = tau > 0 ? 1.0 - Math.Exp(-1.0 / (fps * tau)) : 1.0;
            upFrame = easeIn > 0 ? 1.0 / (fps * easeIn) : double.PositiveInfinity;
            downFrame = easeOut > 0 ? 1.0 / (fps * easeOut) : double.PositiveInfinity;
        }

        /// <summary>The eased opacity after the last Step / Update (0 before the first).</summary>
        public float Value { get { return (float)value; } }

        /// <summary>Forget the history: the next call starts at its opacity (e.g. after a seek).</summary>
        public void Reset() { started = false; value = 0; smooth = 0; }

        /// <summary>Advance one video frame (1 / fps seconds) towards opacity; returns the eased value.</summary>
        public float Step(float opacity)
        {
            return Advance(opacity, aFrame, upFrame, downFrame);
        }

        /// <summary>Advance dtS seconds towards opacity; returns the eased value.</summary>
        public float Update(float opacity, double dtS)
        {
            double dt = Math.Max(0.0, dtS);
            return Advance(opacity, tau > 0 ? 1.0 - Math.Exp(-dt / tau) : 1.0,
                           easeIn > 0 ? dt / easeIn : double.PositiveInfinity,
                           easeOut > 0 ? dt / easeOut : double.PositiveInfinity);
        }

        float Advance(double x, double a, double up, double down)
        {
            if (!started) { smooth = x; value = x; started = true; }
            smooth = smooth + a * (x - smooth);
            double d = smooth - value;
            value = value + (d > 0 ? Math.Min(d, up) : Math.Max(d, -down));
            return (float)value;
        }
    }

    // ======================================================================== paper mode
    /// <summary>
    /// simulator.epof.ViewportOverlaps, ported: the overlap of the viewport with every window,
    /// tabulated over viewport pitch x roll x yaw offset within one yaw step (built at load,
    /// ~1 s) and interpolated trilinearly; EPOF = sum POF OL / sum OL.
    /// </summary>
    internal sealed class PaperModel
    {
        internal readonly int P, Y;
        readonly int nU, nP, nR;
        readonly double step, yawStart, dp, dr;
        internal readonly float[] Table; // (nP, nR, nU + 1, P, Y)
        readonly double[] centres;       // P*Y*3 window centre directions
        readonly int[] corner = new int[8];

        public PaperModel(double[] yawDeg, double[] pitchDeg, double yawStepDeg, double yawStartDeg,
                          double winHfov, double winVfov, double hfov, double vfov,
                          double pitchStep, double rollStep, double yawTableStep, int rays,
                          double latStep, double lonStep)
        {
            P = pitchDeg.Length; Y = yawDeg.Length;
            step = yawStepDeg; yawStart = yawStartDeg;
            nU = Math.Max(1, (int)Math.Ceiling(step / yawTableStep - 1e-9));
            double du = step / nU, invDu = 1.0 / du;
            int n = Y * nU;
            nP = (int)VimsimEpof.RoundEven(180.0 / pitchStep) + 1;
            nR = (int)VimsimEpof.RoundEven(360.0 / rollStep) + 1;
            double[] pg = Linspace(-90.0, 90.0, nP), rg = Linspace(-180.0, 180.0, nR);
            dp = pg[1] - pg[0]; dr = rg[1] - rg[0];

            int nLat, R;
            double[] runStart, runLen; // (P, nLat, R)
            WindowRuns(pitchDeg, winHfov, winVfov, latStep, lonStep, out nLat, out R, out runStart, out runLen);

            // Viewport rays (perspective_rays: float32 directions and solid angles).
            int nr = rays * rays;
            var dx = new double[nr]; var dy = new double[nr]; var dz = new double[nr]; var sa = new double[nr];
            double tx = Math.Tan(VimsimEpof.Rad(hfov) / 2.0), ty = Math.Tan(VimsimEpof.Rad(vfov) / 2.0);
            double omega = 0;
            for (int j = 0; j < rays; j++)
                for (int i = 0; i < rays; i++)
                {
                    double u = ((i + 0.5) / rays * 2.0 - 1.0) * tx;
                    double v = (1.0 - (j + 0.5) / rays * 2.0) * ty;
                    double r2 = 1.0 + u * u + v * v, rn = Math.Sqrt(r2);
                    int k = j * rays + i;
                    dx[k] = (float)(u / rn); dy[k] = (float)(v / rn); dz[k] = (float)(1.0 / rn);
                    sa[k] = (float)((2.0 * tx / rays) * (2.0 * ty / rays) / (r2 * rn));
                    omega += sa[k];
                }

            var table = new float[nP * nR * (nU + 1) * P * Y];
            // One pitch row of the table per task (entries are independent: same numbers on any
            // number of cores).
            System.Threading.Tasks.Parallel.For(0, nP, ip =>
            {
                var diff = new double[P * (2 * n + 1)];
                var B = new double[P * n];
                var bandOf = new int[nr];
                var lonOf = new double[nr];
                var cs = new double[2 * n];
                for (int jr = 0; jr < nR; jr++)
                {
                    double[] M = VimsimEpof.HeadRotation(0.0, VimsimEpof.Rad(pg[ip]), VimsimEpof.Rad(rg[jr]));
                    for (int k = 0; k < nr; k++)
                    {
                        double wx = dx[k] * M[0] + dy[k] * M[1] + dz[k] * M[2];
                        double wy = dx[k] * M[3] + dy[k] * M[4] + dz[k] * M[5];
                        double wz = dx[k] * M[6] + dy[k] * M[7] + dz[k] * M[8];
                        lonOf[k] = Math.Atan2(wx, wz) * (180.0 / Math.PI);
                        double lat = Math.Asin(Math.Max(-1.0, Math.Min(1.0, wy))) * (180.0 / Math.PI);
                        int b = (int)((lat + 90.0) / latStep);
                        bandOf[k] = b < 0 ? 0 : b > nLat - 1 ? nLat - 1 : b;
                    }
                    Array.Clear(diff, 0, diff.Length);
                    for (int p = 0; p < P; p++)
                    {
                        int poff = p * (2 * n + 1), pq = p * nLat;
                        for (int k = 0; k < nr; k++)
                        {
                            int q0 = (pq + bandOf[k]) * R;
                            double lonk = lonOf[k];
                            for (int r = 0; r < R; r++)
                            {
                                double L = runLen[q0 + r];
                                if (L <= 0) continue;
                                double s = runStart[q0 + r];
                                // the lattice points j du (relative yaw) with s <= lon + j du <= s + L
                                // (1e-9 step of slack: a ray exactly on an edge is inside)
                                double lo = Math.Ceiling((s - lonk) * invDu - 1e-9);
                                double hi = Math.Floor((s + L - lonk) * invDu + 1e-9);
                                int cnt = (int)(hi - lo) + 1;
                                if (cnt <= 0) continue;
                                if (cnt > n) cnt = n;
                                int j0 = (int)lo % n;
                                if (j0 < 0) j0 += n;
                                diff[poff + j0] += sa[k];
                                diff[poff + j0 + cnt] -= sa[k];
                            }
                        }
                        double acc = 0;
                        for (int j = 0; j < 2 * n; j++) { acc += diff[poff + j]; cs[j] = acc; }
                        for (int j = 0; j < n; j++) B[p * n + j] = (cs[j] + cs[j + n]) / omega;
                    }
                    int baseIdx = (ip * nR + jr) * (nU + 1);
                    for (int u = 0; u <= nU; u++)
                    {
                        int o = (baseIdx + u) * P * Y;
                        for (int p = 0; p < P; p++)
                            for (int m = 0; m < Y; m++)
                                table[o + p * Y + m] = (float)B[p * n + (m * nU + u) % n];
                    }
                }
            });
            Table = table;
            int nu1 = nU + 1, c = 0;
            for (int a = 0; a < 2; a++)
                for (int b = 0; b < 2; b++)
                    for (int cc = 0; cc < 2; cc++)
                        corner[c++] = a * nR * nu1 + b * nu1 + cc;
            centres = new double[P * Y * 3];
            for (int p = 0; p < P; p++)
                for (int y = 0; y < Y; y++)
                {
                    double cp = VimsimEpof.Rad(pitchDeg[p]), cyw = VimsimEpof.Rad(yawDeg[y]);
                    int o = (p * Y + y) * 3;
                    centres[o] = Math.Sin(cyw) * Math.Cos(cp); centres[o + 1] = Math.Sin(cp); centres[o + 2] = Math.Cos(cyw) * Math.Cos(cp);
                }
        }

        static double[] Linspace(double a, double b, int num)
        {
            var y = new double[num];
            double s = (b - a) / (num - 1);
            for (int i = 0; i < num; i++) y[i] = i * s + a;
            y[num - 1] = b;
            return y;
        }

        /// <summary>simulator.epof._window_runs: each window row's membership as runs of
        /// window-relative longitude per latitude band (float32 inside test, as numpy).</summary>
        static void WindowRuns(double[] pitchDeg, double hfov, double vfov, double latStep, double lonStep,
                               out int nLat, out int R, out double[] start, out double[] length)
        {
            int nLt = (int)VimsimEpof.RoundEven(180.0 / latStep);
            nLat = nLt;
            int nLon = (int)VimsimEpof.RoundEven(360.0 / lonStep);
            int P = pitchDeg.Length;
            var sinLon = new double[nLon]; var cosLon = new double[nLon];
            for (int j = 0; j < nLon; j++)
            {
                double lon = VimsimEpof.Rad(-180.0 + (j + 0.5) * lonStep);
                sinLon[j] = Math.Sin(lon); cosLon[j] = Math.Cos(lon);
            }
            float tx = (float)Math.Tan(VimsimEpof.Rad(hfov) / 2), ty = (float)Math.Tan(VimsimEpof.Rad(vfov) / 2);
            var runs = new List<double[]>[P * nLt];
            System.Threading.Tasks.Parallel.For(0, P, p =>
            {
                var inside = new bool[nLon];
                // head_rotation(0, pitch, 0) = Rx(-pitch), as float32 (scipy's quaternion formula).
                double half = VimsimEpof.Rad(-pitchDeg[p]) / 2.0;
                double qx = Math.Sin(half), qw = Math.Cos(half);
                float m11 = (float)(qw * qw - qx * qx), m12 = (float)(-2.0 * qx * qw), m21 = (float)(2.0 * qx * qw), m22 = m11;
                for (int b = 0; b < nLt; b++)
                {
                    double lat = VimsimEpof.Rad(-90.0 + (b + 0.5) * latStep);
                    double cl = Math.Cos(lat);
                    float d1 = (float)Math.Sin(lat);
                    bool all = true, any = false;
                    for (int j = 0; j < nLon; j++)
                    {
                        float d0 = (float)(cl * sinLon[j]), d2 = (float)(cl * cosLon[j]);
                        // w = d @ m (float32): w0 = d0, w1 = d1 m11 + d2 m21, w2 = d1 m12 + d2 m22
                        float w1 = (float)((float)(d1 * m11) + (float)(d2 * m21));
                        float w2 = (float)((float)(d1 * m12) + (float)(d2 * m22));
                        bool ins = w2 > 0 && Math.Abs(d0) <= (float)(tx * w2) && Math.Abs(w1) <= (float)(ty * w2);
                        inside[j] = ins;
                        all &= ins; any |= ins;
                    }
                    var list = new List<double[]>();
                    if (all) list.Add(new double[] { -180.0, 360.0 });
                    else if (any)
                    {
                        var starts = new List<int>(); var ends = new List<int>();
                        for (int j = 0; j < nLon; j++)
                        {
                            if (inside[j] && !inside[(j - 1 + nLon) % nLon]) starts.Add(j);
                            if (inside[j] && !inside[(j + 1) % nLon]) ends.Add(j);
                        }
                        if (ends[0] < starts[0]) { int e0 = ends[0]; ends.RemoveAt(0); ends.Add(e0); }
                        for (int k = 0; k < starts.Count; k++)
                        {
                            int L = ((ends[k] - starts[k]) % nLon + nLon) % nLon + 1;
                            list.Add(new double[] { -180.0 + starts[k] * lonStep, L * lonStep });
                        }
                    }
                    runs[p * nLt + b] = list;
                }
            });
            int maxR = 1;
            foreach (var list in runs) maxR = Math.Max(maxR, list.Count);
            R = maxR;
            start = new double[P * nLat * R];
            length = new double[P * nLat * R];
            for (int q = 0; q < P * nLat; q++)
                for (int k = 0; k < runs[q].Count; k++)
                {
                    start[q * R + k] = runs[q][k][0];
                    length[q * R + k] = runs[q][k][1];
                }
        }

        /// <summary>EPOF of one viewport; ol: scratch of P * Y doubles (per caller: the table is shared).</summary>
        public double Query(float[] pof, int off, double yaw, double pitch, double roll, double[] ol)
        {
            if (pitch > 90.0 || pitch < -90.0)
            {   // re-express the same rotation with pitch in [-90, 90] (yaw + 180, 180 - pitch, roll + 180)
                double p2 = VimsimEpof.Wrap180(pitch);
                if (p2 > 90.0) { yaw += 180.0; pitch = 180.0 - p2; roll += 180.0; }
                else if (p2 < -90.0) { yaw += 180.0; pitch = -180.0 - p2; roll += 180.0; }
                else pitch = p2;
                yaw = VimsimEpof.Wrap180(yaw);
            }
            roll = VimsimEpof.PyMod(roll + 180.0, 360.0) - 180.0;
            double fp = (pitch + 90.0) / dp;
            int i0 = Clamp((int)Math.Floor(fp), 0, nP - 2);
            double wp = fp - i0;
            double fr = (roll + 180.0) / dr;
            int j0 = Clamp((int)Math.Floor(fr), 0, nR - 2);
            double wr = fr - j0;
            double a = (yaw - yawStart) / step;
            double kf = Math.Floor(a);
            double fu = (a - kf) * nU;
            int u0 = Clamp((int)Math.Floor(fu), 0, nU - 1);
            double wu = fu - u0;
            int k = (int)VimsimEpof.PyMod(kf, Y);
            int baseRow = (i0 * nR + j0) * (nU + 1) + u0;
            int PY = P * Y;
            Array.Clear(ol, 0, PY);
            int c = 0;
            for (int ia = 0; ia < 2; ia++)
                for (int ib = 0; ib < 2; ib++)
                    for (int ic = 0; ic < 2; ic++)
                    {
                        double w = (ia == 0 ? 1 - wp : wp) * (ib == 0 ? 1 - wr : wr) * (ic == 0 ? 1 - wu : wu);
                        int o = (baseRow + corner[c++]) * PY;
                        if (w == 0) continue;
                        for (int q = 0; q < PY; q++) ol[q] += w * Table[o + q];
                    }
            double num = 0, den = 0;
            for (int p = 0; p < P; p++)
            {
                int rowOff = off + p * Y, po = p * Y;
                for (int m = 0; m < Y; m++)
                {
                    int col = k - m; if (col < 0) col += Y;
                    double w = ol[po + m];
                    num += w * pof[rowOff + col];
                    den += w;
                }
            }
            if (den > 1e-6) return num / den;
            // Viewport outside every window: the flow of the window nearest the view axis.
            double[] Rm = VimsimEpof.HeadRotation(VimsimEpof.Rad(yaw), VimsimEpof.Rad(pitch), VimsimEpof.Rad(roll));
            double fx = Rm[2], fy = Rm[5], fz = Rm[8], best = double.NegativeInfinity;
            int near = 0;
            for (int q = 0; q < PY; q++)
            {
                double dot = fx * centres[3 * q] + fy * centres[3 * q + 1] + fz * centres[3 * q + 2];
                if (dot > best) { best = dot; near = q; }
            }
            return pof[off + near];
        }

        static int Clamp(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }
    }

    // ======================================================================= sphere mode
    /// <summary>
    /// simulator.sphere.ViewportQuery, ported: exact EPOF = sum_c f_c w_c / sum_c w_c over the
    /// lon/lat cells, w_c the solid angle of cell c inside the viewport; weights computed per
    /// (pitch, roll, yaw mod one cell) bin of query_step_deg and cached, the yaw's whole cells
    /// applied as a column shift.
    /// </summary>
    internal sealed class SphereModel
    {
        internal readonly int NLat, NLon;
        readonly int nSub, cacheSize;
        readonly double c, invC, st, radius;
        readonly double[] normals; // 4 x 3, head frame
        readonly double[] rowCl, rowSl, rowHalfE, rowSa, colSin, colCos;
        readonly double halfN;
        readonly Dictionary<long, Bin> bins = new Dictionary<long, Bin>();
        readonly Queue<long> order = new Queue<long>();
        double[] scratchW = new double[0];
        int[] scratchR = new int[0], scratchC = new int[0];
        readonly double[] nw = new double[12], hk = new double[4], phik = new double[4], hRow = new double[4], nySl = new double[4];
        int[] cand = new int[16], inner = new int[16], tmp = new int[16];
        readonly int[] arc = new int[4], arcS0 = new int[8], arcLen = new int[8];
        int nInner, cutMask;
        int[] runRowS = new int[64], runJ0S = new int[64], runJ1S = new int[64];
        double[] runSaS = new double[64];

        /// <summary>One bin's weights: interior runs (row, columns [j0, j1), each weighing the
        /// row's cell area: coverage 1) and the boundary cells with their own weights.</summary>
        sealed class Bin
        {
            public int count, runs;
            public int[] rowBase, cols, runRow, runJ0, runJ1;
            public double[] w, runSa;
            public double wsum;
        }
        Bin spare; // the last evicted bin: its arrays are reused

        public SphereModel(double cellDeg, double stepDeg, double hfov, double vfov, int cacheBins)
        {
            NLat = (int)VimsimEpof.RoundEven(180.0 / cellDeg);
            NLon = 2 * NLat;
            st = stepDeg;
            nSub = (int)VimsimEpof.RoundEven(cellDeg / stepDeg);
            cacheSize = cacheBins > 0 ? cacheBins : 4096;
            c = VimsimEpof.Rad(cellDeg);
            invC = 1.0 / c;
            double lf = VimsimEpof.Rad(hfov / 2.0), up = VimsimEpof.Rad(vfov / 2.0);
            normals = new double[] {
                Math.Cos(lf), 0.0, Math.Sin(lf),
                -Math.Cos(lf), 0.0, Math.Sin(lf),
                0.0, Math.Cos(up), Math.Sin(up),
                0.0, -Math.Cos(up), Math.Sin(up) };
            double t = Math.Tan(lf), tv = Math.Tan(up);
            radius = Math.Atan(Math.Sqrt(t * t + tv * tv)) + c;
            rowCl = new double[NLat]; rowSl = new double[NLat]; rowHalfE = new double[NLat]; rowSa = new double[NLat];
            for (int i = 0; i < NLat; i++)
            {
                double lat = Math.PI / 2 - (i + 0.5) * c;
                rowCl[i] = Math.Cos(lat); rowSl[i] = Math.Sin(lat);
                rowSa[i] = c * (Math.Sin(lat + c / 2) - Math.Sin(lat - c / 2));
                double edge = Math.Abs(Math.Cos(lat - Math.Sign(lat) * c / 2));
                rowHalfE[i] = 0.5 * c * Math.Max(rowCl[i], edge);
            }
            halfN = 0.5 * c;
            colSin = new double[NLon]; colCos = new double[NLon];
            for (int j = 0; j < NLon; j++)
            {
                double lon = -Math.PI + (j + 0.5) * c;
                colSin[j] = Math.Sin(lon); colCos[j] = Math.Cos(lon);
            }
        }

        public int CachedBins { get { return bins.Count; } }

        /// <summary>EPOF of one orientation from one frame's running sums P (off: the frame's
        /// first; per cell row NLon + 1 values, P[0] = 0, cell j = P[j + 1] - P[j]).</summary>
        public double Query(double[] P, int off, double yaw, double pitch, double roll)
        {
            if (pitch > 90.0 || pitch < -90.0)
            {   // the same rotation with pitch in [-90, 90]
                double p2 = VimsimEpof.Wrap180(pitch);
                if (p2 > 90.0) { yaw += 180.0; pitch = 180.0 - p2; roll += 180.0; }
                else if (p2 < -90.0) { yaw += 180.0; pitch = -180.0 - p2; roll += 180.0; }
                else pitch = p2;
            }
            long M = (long)NLon * nSub;
            long y = VimsimEpof.RoundEven(yaw / st) % M;
            if (y < 0) y += M;
            int shift = (int)(y / nSub), sub = (int)(y % nSub);
            int ip = (int)VimsimEpof.RoundEven(Math.Max(-90.0, Math.Min(90.0, pitch)) / st);
            int ir = (int)VimsimEpof.RoundEven((VimsimEpof.PyMod(roll + 180.0, 360.0) - 180.0) / st);
            long key = (((long)ip + 100000) * 200000 + (ir + 100000)) * 1000 + sub;
            Bin b;
            if (!bins.TryGetValue(key, out b))
            {
                if (bins.Count >= cacheSize)
                {
                    long old = order.Dequeue();
                    spare = bins[old];
                    bins.Remove(old);
                }
                b = Compute(sub * st, ip * st, ir * st);
                bins[key] = b;
                order.Enqueue(key);
            }
            double s = 0;
            int nLon = NLon;
            int[] rr = b.runRow, r0 = b.runJ0, r1 = b.runJ1;
            double[] rs = b.runSa;
            for (int q = 0, nq = b.runs; q < nq; q++)
            {   // columns j0 + shift .. j1 + shift, wrapping at nLon: one or two contiguous pieces
                int o = off + rr[q], a = r0[q] + shift, e = r1[q] + shift;
                if (a >= nLon) { a -= nLon; e -= nLon; }
                double t = e <= nLon ? P[o + e] - P[o + a] : (P[o + nLon] - P[o + a]) + P[o + e - nLon];
                s += t * rs[q];
            }
            int[] rb = b.rowBase, cols = b.cols;
            double[] w = b.w;
            for (int q = 0, nq = b.count; q < nq; q++)
            {
                int col = cols[q] + shift;
                if (col >= nLon) col -= nLon;
                int o = off + rb[q] + col;
                s += (P[o + 1] - P[o]) * w[q];
            }
            return s / b.wsum;
        }

        /// <summary>
        /// The weights of one bin: w_c = A_c prod_k clip(0.5 + 0.5 d_k / hw_k, 0, 1) over the 4
        /// frustum planes (d_k: signed distance of the cell centre, hw_k: the cell's half extent
        /// along the normal), kept where w > max(w) 1e-7, rows as simulator.sphere's band. Per
        /// row, d_k(lon) = rho_k cos(lon - phi_k) + ny_k sin(lat) and hw_k <= H_k, so the columns
        /// with d_k > -H_k for every plane (all others weigh exactly 0) and those with d_k >= H_k
        /// for every plane (weight exactly A_c) are arcs found analytically (with AcosSlack of
        /// margin); only the columns in between get the formula.
        /// </summary>
        Bin Compute(double yawDeg, double pitchDeg, double rollDeg)
        {
            double[] R = VimsimEpof.HeadRotation(VimsimEpof.Rad(yawDeg), VimsimEpof.Rad(pitchDeg), VimsimEpof.Rad(rollDeg));
            for (int k = 0; k < 4; k++)
            {   // plane normals in the world frame: n_world = R n_head
                for (int i = 0; i < 3; i++)
                    nw[3 * k + i] = R[3 * i] * normals[3 * k] + R[3 * i + 1] * normals[3 * k + 1] + R[3 * i + 2] * normals[3 * k + 2];
                hk[k] = Math.Sqrt(nw[3 * k] * nw[3 * k] + nw[3 * k + 2] * nw[3 * k + 2]);
                phik[k] = Math.Atan2(nw[3 * k], nw[3 * k + 2]);
            }
            double axisLat = Math.Asin(Math.Max(-1.0, Math.Min(1.0, R[5])));
            int i0 = Math.Max(0, (int)Math.Floor((Math.PI / 2 - axisLat - radius) / c));
            int i1 = Math.Min(NLat, (int)Math.Floor((Math.PI / 2 - axisLat + radius) / c) + 1);
            int cap = (i1 - i0) * NLon;
            if (scratchW.Length < cap) { scratchW = new double[cap]; scratchR = new int[cap]; scratchC = new int[cap]; }
            int cnt = 0, nRun = 0;
            double wmax = 0, minBoundary = double.PositiveInfinity;
            // Locals: Mono does not hoist field loads out of loops.
            double[] sw = scratchW, cs = colSin, cc = colCos;
            int[] sr = scratchR, sc = scratchC;
            double hn = halfN;
            int nLon = NLon;
            for (int i = i0; i < i1; i++)
            {
                double cl = rowCl[i], sl = rowSl[i], he = rowHalfE[i], sa = rowSa[i];
                int rowBase = i * (nLon + 1); // into the running sums
                int nc = RowArcs(cl, sl, he);
                if (nc == 0) continue;
                int ni = nInner, cut = cutMask;
                for (int q = 0; q < ni; q++)
                {   // interior runs: coverage exactly 1, weight = the row's cell area
                    if (nRun == runRowS.Length) GrowRuns();
                    runRowS[nRun] = rowBase; runJ0S[nRun] = inner[2 * q]; runJ1S[nRun] = inner[2 * q + 1];
                    runSaS[nRun] = sa;
                    nRun++;
                    if (sa > wmax) wmax = sa;
                }
                // Per plane that cuts this row (the others weigh 1 on every candidate): d = n .
                // centre = ax so + az co + s and the half extent hw = |ex co - ez so| + |c - gx so -
                // gz co| + 1e-9 (simulator.sphere's |n . east_half| + |n . north_half| + 1e-9),
                // so = sin lon, co = cos lon; coverage clip(0.5 + 0.5 d / hw, 0, 1), 1 for d >= H.
                bool cut0 = (cut & 1) != 0, cut1 = (cut & 2) != 0, cut2 = (cut & 4) != 0, cut3 = (cut & 8) != 0;
                double h0 = hRow[0], h1 = hRow[1], h2 = hRow[2], h3 = hRow[3];
                double s0 = nySl[0], s1 = nySl[1], s2 = nySl[2], s3 = nySl[3];
                double hs = hn * sl, hc = hn * cl;
                double nx0 = nw[0], ny0 = nw[1], nz0 = nw[2];
                double ax0 = cl * nx0, az0 = cl * nz0, ex0 = he * nx0, ez0 = he * nz0, c0 = hc * ny0, gx0 = hs * nx0, gz0 = hs * nz0;
                double nx1 = nw[3], ny1 = nw[4], nz1 = nw[5];
                double ax1 = cl * nx1, az1 = cl * nz1, ex1 = he * nx1, ez1 = he * nz1, c1 = hc * ny1, gx1 = hs * nx1, gz1 = hs * nz1;
                double nx2 = nw[6], ny2 = nw[7], nz2 = nw[8];
                double ax2 = cl * nx2, az2 = cl * nz2, ex2 = he * nx2, ez2 = he * nz2, c2 = hc * ny2, gx2 = hs * nx2, gz2 = hs * nz2;
                double nx3 = nw[9], ny3 = nw[10], nz3 = nw[11];
                double ax3 = cl * nx3, az3 = cl * nz3, ex3 = he * nx3, ez3 = he * nz3, c3 = hc * ny3, gx3 = hs * nx3, gz3 = hs * nz3;
                int iq = 0;
                for (int q = 0; q < nc; q++)
                {
                    int cur = cand[2 * q], ce = cand[2 * q + 1];
                    while (cur < ce)
                    {   // the next boundary piece: candidate columns outside the interior runs
                        while (iq < ni && inner[2 * iq + 1] <= cur) iq++;
                        int pe = ce;
                        if (iq < ni && inner[2 * iq] < ce)
                        {
                            if (inner[2 * iq] <= cur) { cur = inner[2 * iq + 1]; continue; }
                            pe = inner[2 * iq];
                        }
                        for (int j = cur; j < pe; j++)
                        {
                            double so = cs[j], co = cc[j], cov = 1.0, d, hw, t;
                            if (cut0 && (d = ax0 * so + az0 * co + s0) < h0)
                            {
                                if (d <= -h0) continue;
                                t = ex0 * co - ez0 * so; hw = t < 0 ? -t : t;
                                t = c0 - gx0 * so - gz0 * co; hw += (t < 0 ? -t : t) + 1e-9;
                                if (d <= -hw) continue;
                                if (d < hw) cov *= 0.5 + 0.5 * d / hw;
                            }
                            if (cut1 && (d = ax1 * so + az1 * co + s1) < h1)
                            {
                                if (d <= -h1) continue;
                                t = ex1 * co - ez1 * so; hw = t < 0 ? -t : t;
                                t = c1 - gx1 * so - gz1 * co; hw += (t < 0 ? -t : t) + 1e-9;
                                if (d <= -hw) continue;
                                if (d < hw) cov *= 0.5 + 0.5 * d / hw;
                            }
                            if (cut2 && (d = ax2 * so + az2 * co + s2) < h2)
                            {
                                if (d <= -h2) continue;
                                t = ex2 * co - ez2 * so; hw = t < 0 ? -t : t;
                                t = c2 - gx2 * so - gz2 * co; hw += (t < 0 ? -t : t) + 1e-9;
                                if (d <= -hw) continue;
                                if (d < hw) cov *= 0.5 + 0.5 * d / hw;
                            }
                            if (cut3 && (d = ax3 * so + az3 * co + s3) < h3)
                            {
                                if (d <= -h3) continue;
                                t = ex3 * co - ez3 * so; hw = t < 0 ? -t : t;
                                t = c3 - gx3 * so - gz3 * co; hw += (t < 0 ? -t : t) + 1e-9;
                                if (d <= -hw) continue;
                                if (d < hw) cov *= 0.5 + 0.5 * d / hw;
                            }
                            double w = cov * sa;
                            if (w < minBoundary) minBoundary = w;
                            sw[cnt] = w;
                            sr[cnt] = rowBase;
                            sc[cnt] = j;
                            cnt++;
                            if (w > wmax) wmax = w;
                        }
                        cur = pe;
                    }
                }
            }
            // simulator.sphere keeps w > max(w) 1e-7: only boundary cells can be that small.
            double thr = wmax * 1e-7;
            int keep = cnt;
            if (minBoundary <= thr)
            {
                keep = 0;
                for (int q = 0; q < cnt; q++)
                    if (sw[q] > thr)
                    {
                        sw[keep] = sw[q]; sr[keep] = sr[q]; sc[keep] = sc[q];
                        keep++;
                    }
            }
            Bin bin = spare ?? new Bin();
            spare = null;
            if (bin.w == null || bin.w.Length < keep)
            {
                int size = keep + keep / 4 + 8;
                bin.w = new double[size]; bin.rowBase = new int[size]; bin.cols = new int[size];
            }
            if (bin.runSa == null || bin.runSa.Length < nRun)
            {
                int size = nRun + nRun / 4 + 8;
                bin.runSa = new double[size]; bin.runRow = new int[size]; bin.runJ0 = new int[size]; bin.runJ1 = new int[size];
            }
            Array.Copy(sw, bin.w, keep);
            Array.Copy(sr, bin.rowBase, keep);
            Array.Copy(sc, bin.cols, keep);
            Array.Copy(runSaS, bin.runSa, nRun);
            Array.Copy(runRowS, bin.runRow, nRun);
            Array.Copy(runJ0S, bin.runJ0, nRun);
            Array.Copy(runJ1S, bin.runJ1, nRun);
            double wsum = 0;
            for (int q = 0; q < nRun; q++) wsum += runSaS[q] * (runJ1S[q] - runJ0S[q]);
            for (int q = 0; q < keep; q++) wsum += sw[q];
            bin.count = keep;
            bin.runs = nRun;
            bin.wsum = wsum;
            return bin;
        }

        void GrowRuns()
        {
            int n = 2 * runRowS.Length;
            Array.Resize(ref runRowS, n); Array.Resize(ref runJ0S, n); Array.Resize(ref runJ1S, n); Array.Resize(ref runSaS, n);
        }

        /// <summary>acos(x), x in [-1, 1], within 6.8e-5 rad (Abramowitz and Stegun 4.4.45).</summary>
        const double AcosSlack = 1e-4; // rad, > AcosApprox's error

        static double AcosApprox(double x)
        {
            double ax = x < 0 ? -x : x;
            double r = Math.Sqrt(1.0 - ax) * (1.5707288 + ax * (-0.2121144 + ax * (0.0742610 - 0.0187293 * ax)));
            return x < 0 ? Math.PI - r : r;
        }

        /// <summary>
        /// One row's arcs (cos lat cl, sin lat sl, the cells' east half extent he): per plane k
        /// the bound H_k of the half extent (hRow) and ny_k sin lat (nySl), the columns where
        /// d_k > -H_k (cand arc, grown by AcosSlack) and where d_k >= H_k (inner arc, shrunk);
        /// cand = the intersection of the 4 cand arcs (returned count of ranges), inner (count
        /// nInner) that of the inner arcs, cutMask bit k set where plane k's inner arc does not
        /// hold every candidate column. All in one method: Mono inlines almost nothing.
        /// </summary>
        int RowArcs(double cl, double sl, double he)
        {
            int nLon = NLon;
            double asl = sl < 0 ? -sl : sl, hn = halfN, ic = invC;
            int[] cs0 = arcS0, clen = arcLen; // [k] cand, [4 + k] inner
            for (int k = 0; k < 4; k++)
            {
                double ny = nw[3 * k + 1], h = hk[k], phi = phik[k];
                double H = he * h + hn * ((ny < 0 ? -ny : ny) * cl + asl * h) + 1e-9, nys = ny * sl;
                hRow[k] = H; nySl[k] = nys;
                double rho = cl * h, bc = -H - nys, bi = H - nys, inv = rho < 1e-12 ? 0.0 : 1.0 / rho;
                // acos(x) within 6.8e-5 rad (Abramowitz and Stegun 4.4.45); grown / shrunk by
                // AcosSlack the arc holds / lies within the exact one, so no column with any
                // weight is missed and every interior one is truly interior.
                {   // cand: rho cos(lon - phi) >= bc, grown
                    int len, s0 = 0;
                    double x = bc * inv;
                    if (rho < 1e-12) len = 0 > bc - 1e-12 ? nLon : 0; // constant in lon
                    else if (x <= -1.0) len = nLon;
                    else
                    {
                        if (x > 1.0) x = 1.0;
                        double ax = x < 0 ? -x : x;
                        double r = Math.Sqrt(1.0 - ax) * (1.5707288 + ax * (-0.2121144 + ax * (0.0742610 - 0.0187293 * ax)));
                        double al = (x < 0 ? Math.PI - r : r) + AcosSlack;
                        double fa = (phi - al + Math.PI) * ic - 0.5, fb = (phi + al + Math.PI) * ic - 0.5;
                        int a0 = (int)fa, a1 = (int)fb;  // ceil(fa), floor(fb) (truncation toward 0, fixed)
                        if (a0 < fa) a0++;
                        if (fb < 0 && a1 > fb) a1--;
                        len = a1 - a0 + 1;
                        if (len <= 0) len = 0;
                        else if (len >= nLon) len = nLon;
                        else
                        {
                            while (a0 < 0) a0 += nLon;
                            while (a0 >= nLon) a0 -= nLon;
                            s0 = a0;
                        }
                    }
                    cs0[0 + k] = s0; clen[0 + k] = len;
                }
                {   // inner: rho cos(lon - phi) >= bi, shrunk
                    int len, s0 = 0;
                    double x = bi * inv;
                    if (rho < 1e-12) len = 0 >= bi + 1e-12 ? nLon : 0; // constant in lon
                    else if (x <= -1.0) len = x < -1.0 - 1e-12 ? nLon : 0;
                    else if (x >= 1.0) len = 0;
                    else
                    {
                        double ax = x < 0 ? -x : x;
                        double r = Math.Sqrt(1.0 - ax) * (1.5707288 + ax * (-0.2121144 + ax * (0.0742610 - 0.0187293 * ax)));
                        double al = (x < 0 ? Math.PI - r : r) - AcosSlack;
                        double fa = (phi - al + Math.PI) * ic - 0.5, fb = (phi + al + Math.PI) * ic - 0.5;
                        int a0 = (int)fa, a1 = (int)fb;  // ceil(fa), floor(fb) (truncation toward 0, fixed)
                        if (a0 < fa) a0++;
                        if (fb < 0 && a1 > fb) a1--;
                        len = a1 - a0 + 1;
                        if (len <= 0) len = 0;
                        else if (len >= nLon) len = nLon;
                        else
                        {
                            while (a0 < 0) a0 += nLon;
                            while (a0 >= nLon) a0 -= nLon;
                            s0 = a0;
                        }
                    }
                    cs0[4 + k] = s0; clen[4 + k] = len;
                }
            }
            // Intersections; the usual case inline: one range [lo, hi) and arcs that do not wrap
            // (Compute's viewport faces longitude 0 +- a cell: arcs wrap only near the poles).
            int nc = 1, lo = 0, hi = nLon;
            bool one = true;
            for (int k = 0; k < 4; k++)
            {
                int len = clen[k], s0 = cs0[k];
                if (len >= nLon) continue;
                if (len == 0) return 0;
                if (one && s0 + len <= nLon)
                {
                    if (s0 > lo) lo = s0;
                    if (s0 + len < hi) hi = s0 + len;
                    if (lo >= hi) return 0;
                    continue;
                }
                if (one) { cand[0] = lo; cand[1] = hi; one = false; }
                nc = Intersect(ref cand, nc, s0, len);
                if (nc == 0) return 0;
            }
            if (one) { cand[0] = lo; cand[1] = hi; }
            int ni = 1, cut = 0, clo = lo, chi = hi;
            bool candOne = one;
            lo = 0; hi = nLon; one = true;
            for (int k = 0; k < 4; k++)
            {
                int len = clen[4 + k], s0 = cs0[4 + k];
                if (len >= nLon) continue; // holds every column: does not cut
                if (candOne && s0 + len <= nLon) { if (clo < s0 || chi > s0 + len) cut |= 1 << k; }
                else if (!Within(cand, nc, s0, len)) cut |= 1 << k;
                if (one && len > 0 && s0 + len <= nLon)
                {
                    if (s0 > lo) lo = s0;
                    if (s0 + len < hi) hi = s0 + len;
                    if (lo >= hi) { ni = 0; one = false; }
                    continue;
                }
                if (one) { inner[0] = lo; inner[1] = hi; one = false; }
                ni = Intersect(ref inner, ni, s0, len);
            }
            if (one) { inner[0] = lo; inner[1] = hi; }
            nInner = ni; cutMask = cut;
            return nc;
        }

        /// <summary>
        /// The columns j whose centre longitude lon_j satisfies rho cos(lon_j - phi) >= b, the arc
        /// grown (margin 1) or shrunk (margin -1) by AcosSlack on each side, as len columns from
        /// column s0 (wrapping at NLon): len 0 = none, NLon = the whole row.
        /// </summary>
        int Arc(double rho, double phi, double b, int margin, out int s0)
        {
            s0 = 0;
            if (rho < 1e-12) // constant in lon
                return (margin > 0 ? 0 > b - 1e-12 : 0 >= b + 1e-12) ? NLon : 0;
            double x = b / rho;
            if (x <= -1.0) return margin > 0 || x < -1.0 - 1e-12 ? NLon : 0;
            if (x >= 1.0)
            {
                if (margin < 0) return 0;
                x = 1.0;
            }
            // AcosApprox is within 6.8e-5 rad: grown / shrunk by AcosSlack the arc holds / lies
            // within the exact one, so no column with any weight is missed and every interior
            // column is truly interior.
            double al = AcosApprox(x) + margin * AcosSlack;
            double fa = (phi - al + Math.PI) * invC - 0.5, fb = (phi + al + Math.PI) * invC - 0.5;
            int a0 = (int)fa, a1 = (int)fb;  // ceil(fa), floor(fb) (truncation toward 0, fixed)
            if (a0 < fa) a0++;
            if (fb < 0 && a1 > fb) a1--;
            if (a1 < a0) return 0;
            int len = a1 - a0 + 1;
            if (len >= NLon) return NLon;
            while (a0 < 0) a0 += NLon;
            while (a0 >= NLon) a0 -= NLon;
            s0 = a0;
            return len;
        }

        /// <summary>Whether the sorted column ranges set[0..2n) all lie in the arc (s0, len) of Arc.</summary>
        bool Within(int[] set, int n, int s0, int len)
        {
            if (len >= NLon) return true;
            for (int q = 0; q < n; q++)
            {
                int o = set[2 * q] - s0;
                if (o < 0) o += NLon;
                if (o + set[2 * q + 1] - set[2 * q] > len) return false;
            }
            return true;
        }

        /// <summary>Intersect the sorted column ranges set[0..2n) (pairs [start, end)) with the
        /// arc (s0, len) of Arc; returns the new number of ranges.</summary>
        int Intersect(ref int[] set, int n, int s0, int len)
        {
            if (n == 0 || len == 0) return 0;
            if (len >= NLon) return n;
            if (n == 1 && s0 + len <= NLon)
            {   // one range and an arc that does not wrap: [max, min)
                int lo = set[0] > s0 ? set[0] : s0, hi = set[1] < s0 + len ? set[1] : s0 + len;
                if (lo >= hi) return 0;
                set[0] = lo; set[1] = hi;
                return 1;
            }
            int end = s0 + len;
            // The arc as sorted ranges in [0, NLon): [0, end - NLon) then [s0, NLon) if it wraps.
            int m;
            if (end > NLon) { arc[0] = 0; arc[1] = end - NLon; arc[2] = s0; arc[3] = NLon; m = 2; }
            else { arc[0] = s0; arc[1] = end; m = 1; }
            int outN = 0, p = 0, q = 0;
            while (p < n && q < m)
            {   // two sorted lists of disjoint ranges: merge
                int sa = set[2 * p], sb = set[2 * p + 1], aa = arc[2 * q], ab = arc[2 * q + 1];
                int lo = sa > aa ? sa : aa, hi = sb < ab ? sb : ab;
                if (lo < hi) { tmp[2 * outN] = lo; tmp[2 * outN + 1] = hi; outN++; }
                if (sb < ab) p++; else q++;
            }
            int[] t = set; set = tmp; tmp = t;
            return outN;
        }
    }

    // ============================================================================ helpers
    /// <summary>Typed access to the JSON header; a missing or mistyped key is a VimsimLoadException.</summary>
    internal sealed class Header
    {
        readonly Dictionary<string, object> d;
        readonly string src, where;

        public Header(Dictionary<string, object> d, string src, string where = "")
        {
            this.d = d; this.src = src; this.where = where;
        }

        object Get(string k)
        {
            object v;
            if (!d.TryGetValue(k, out v) || v == null)
                throw new VimsimLoadException(src, "header lacks '" + where + k + "'; not a vimsim export of this version");
            return v;
        }

        public bool Has(string k) { object v; return d.TryGetValue(k, out v) && v != null; }

        public double Num(string k)
        {
            object v = Get(k);
            if (v is double) return (double)v;
            if (v is bool) return (bool)v ? 1 : 0;
            throw new VimsimLoadException(src, "header '" + where + k + "' is not a number");
        }

        public string Str(string k)
        {
            var v = Get(k) as string;
            if (v == null) throw new VimsimLoadException(src, "header '" + where + k + "' is not a string");
            return v;
        }

        public Header Obj(string k)
        {
            var v = Get(k) as Dictionary<string, object>;
            if (v == null) throw new VimsimLoadException(src, "header '" + where + k + "' is not an object");
            return new Header(v, src, where + k + ".");
        }

        public double[] DoubleArray(string k)
        {
            var v = Get(k) as List<object>;
            if (v == null) throw new VimsimLoadException(src, "header '" + where + k + "' is not an array");
            var a = new double[v.Count];
            for (int i = 0; i < a.Length; i++)
            {
                if (!(v[i] is double)) throw new VimsimLoadException(src, "header '" + where + k + "' has a non-number");
                a[i] = (double)v[i];
            }
            return a;
        }

        public int[] IntArray(string k)
        {
            var a = DoubleArray(k);
            var r = new int[a.Length];
            for (int i = 0; i < a.Length; i++) r[i] = (int)a[i];
            return r;
        }
    }

    /// <summary>A small JSON reader: objects (Dictionary), arrays (List), strings, doubles, bools, null.</summary>
    internal static class MiniJson
    {
        public static object Parse(string s)
        {
            int i = 0;
            object v = Value(s, ref i);
            Ws(s, ref i);
            if (i != s.Length) throw new FormatException("unexpected text at character " + i);
            return v;
        }

        static void Ws(string s, ref int i)
        {
            while (i < s.Length && (s[i] == ' ' || s[i] == '\t' || s[i] == '\n' || s[i] == '\r')) i++;
        }

        static object Value(string s, ref int i)
        {
            Ws(s, ref i);
            if (i >= s.Length) throw new FormatException("unexpected end");
            char ch = s[i];
            if (ch == '{')
            {
                var d = new Dictionary<string, object>();
                i++; Ws(s, ref i);
                if (i < s.Length && s[i] == '}') { i++; return d; }
                while (true)
                {
                    Ws(s, ref i);
                    if (i >= s.Length || s[i] != '"') throw new FormatException("expected a key at character " + i);
                    string k = Str(s, ref i);
                    Ws(s, ref i);
                    if (i >= s.Length || s[i] != ':') throw new FormatException("expected ':' at character " + i);
                    i++;
                    d[k] = Value(s, ref i);
                    Ws(s, ref i);
                    if (i < s.Length && s[i] == ',') { i++; continue; }
                    if (i < s.Length && s[i] == '}') { i++; return d; }
                    throw new FormatException("expected ',' or '}' at character " + i);
                }
            }
            if (ch == '[')
            {
                var a = new List<object>();
                i++; Ws(s, ref i);
                if (i < s.Length && s[i] == ']') { i++; return a; }
                while (true)
                {
                    a.Add(Value(s, ref i));
                    Ws(s, ref i);
                    if (i < s.Length && s[i] == ',') { i++; continue; }
                    if (i < s.Length && s[i] == ']') { i++; return a; }
                    throw new FormatException("expected ',' or ']' at character " + i);
                }
            }
            if (ch == '"') return Str(s, ref i);
            if (string.CompareOrdinal(s, i, "true", 0, 4) == 0) { i += 4; return true; }
            if (string.CompareOrdinal(s, i, "false", 0, 5) == 0) { i += 5; return false; }
            if (string.CompareOrdinal(s, i, "null", 0, 4) == 0) { i += 4; return null; }
            int st = i;
            while (i < s.Length && "+-0123456789.eE".IndexOf(s[i]) >= 0) i++;
            double x;
            if (i == st || !double.TryParse(s.Substring(st, i - st), NumberStyles.Float, CultureInfo.InvariantCulture, out x))
                throw new FormatException("bad value at character " + st);
            return x;
        }

        static string Str(string s, ref int i)
        {
            var sb = new StringBuilder();
            i++; // opening quote
            while (i < s.Length)
            {
                char ch = s[i++];
                if (ch == '"') return sb.ToString();
                if (ch != '\\') { sb.Append(ch); continue; }
                if (i >= s.Length) break;
                char e = s[i++];
                switch (e)
                {
                    case '"': sb.Append('"'); break;
                    case '\\': sb.Append('\\'); break;
                    case '/': sb.Append('/'); break;
                    case 'b': sb.Append('\b'); break;
                    case 'f': sb.Append('\f'); break;
                    case 'n': sb.Append('\n'); break;
                    case 'r': sb.Append('\r'); break;
                    case 't': sb.Append('\t'); break;
                    case 'u':
                        if (i + 4 > s.Length) throw new FormatException("bad \\u escape");
                        sb.Append((char)int.Parse(s.Substring(i, 4), NumberStyles.HexNumber, CultureInfo.InvariantCulture));
                        i += 4; break;
                    default: throw new FormatException("bad escape \\" + e);
                }
            }
            throw new FormatException("unterminated string");
        }
    }
}
