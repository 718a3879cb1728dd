// vimsim export: VimsimOverlay.hlsl, the mitigation overlay core (vimsim render's eye.frag, GLES3-safe).
// Draws over the video what `vimsim render` draws: world-fixed grains (a granulated rest frame)
// behind a head-fixed soft cutout, the tunneling vignette, or both; the result is premultiplied
// (rgb * alpha, alpha): blend One OneMinusSrcAlpha over the video. VimsimOverlay.shader includes
// it for the Built-in and URP pipelines; `frag` below is a standalone test entry (glslang, CI).
//
// Conventions (vimsim): world +x right, +y up, +z forward (the equirect centre); lon = atan2(x, z),
// lat = asin(y); eccentricity = angle from the head's forward axis. No storage buffers: the grain
// layout reaches the GPU as a coverage texture (_VimsimGrainMask, equirect, row 0 = north, u = 0 at
// lon -180 deg), built once from the exported layout by VimsimGrainMask.Build (VimsimEpof.cs) with
// the same formula as vimsim's grf_mask.frag. Only texture sampling and float4 constants.
#ifndef VIMSIM_OVERLAY_INCLUDED
#define VIMSIM_OVERLAY_INCLUDED

#define VIMSIM_PI 3.14159265358979

Texture2D _VimsimGrainMask;              // grain coverage 0..1 (R), repeat in u, clamp in v, mipmapped
SamplerState sampler_VimsimGrainMask;    // bilinear (trilinear with mipmaps)

cbuffer UnityPerMaterial
{
    float4 _VimsimHeadRight;     // xyz: the head's +x axis in the world frame of the rays given to VimsimToHead
    float4 _VimsimHeadUp;        // xyz: the head's +y axis
    float4 _VimsimHeadForward;   // xyz: the head's +z axis (view centre)
    float4 _VimsimCutout;        // inner radius, outer radius (radians), grains on (1/0), opacity 0..1
    float4 _VimsimVignette;      // full-view radius r_full, aperture_min / 2, feather (radians), vignette on (1/0)
    float4 _VimsimVignetteColor; // rgb 0..1
    float4 _VimsimMask;          // mask height in texels, mip levels used (1/0), video yaw offset (radians), 0
};

// A Unity world direction in the video's world frame: rotated about +y by the yaw offset
// (VimsimEpof.FromUnityEuler's yawOffsetDeg: the vimsim yaw of Unity's +z).
float3 VimsimUnityToVideo(float3 d)
{
    float s = sin(_VimsimMask.z), c = cos(_VimsimMask.z);
    return float3(c * d.x + s * d.z, d.y, c * d.z - s * d.x);
}

// The head frame of a world direction (the eye's ray).
float3 VimsimToHead(float3 dWorld)
{
    return float3(dot(dWorld, _VimsimHeadRight.xyz), dot(dWorld, _VimsimHeadUp.xyz),
                  dot(dWorld, _VimsimHeadForward.xyz));
}

// Premultiplied overlay colour of one view ray: dWorld, dHead unit vectors of the same ray in
// the world and head frames; footprintRad: the pixel's angular size (max over its two axes).
float4 VimsimOverlay(float3 dWorld, float3 dHead, float footprintRad)
{
    float opacity = saturate(_VimsimCutout.w);
    float ecc = atan2(length(dHead.xy), dHead.z);
    float grainAlpha = 0.0;
    if (_VimsimCutout.z > 0.5)
    {
        float cut = saturate((ecc - _VimsimCutout.x) / (_VimsimCutout.y - _VimsimCutout.x));
        float lon = atan2(dWorld.x, dWorld.z);
        float lat = asin(clamp(dWorld.y, -1.0, 1.0));
        float2 st = float2(lon / (2.0 * VIMSIM_PI) + 0.5, 0.5 - lat / VIMSIM_PI);
        float lod = 0.0;
        if (_VimsimMask.y > 0.5)
            lod = log2(max(footprintRad / (VIMSIM_PI / _VimsimMask.x), 1e-6));
        float cov = _VimsimGrainMask.SampleLevel(sampler_VimsimGrainMask, st, lod).r;
        grainAlpha = cut * opacity * cov;            // black grains
    }
    float3 premul = float3(0.0, 0.0, 0.0);
    float alpha = grainAlpha;
    if (_VimsimVignette.w > 0.5)
    {
        float feather = _VimsimVignette.z;
        float r0 = _VimsimVignette.x + 0.5 * feather;
        float r = r0 + (_VimsimVignette.y - r0) * opacity;
        float va = feather > 0.0 ? saturate((ecc - r) / feather + 0.5) : (ecc >= r ? 1.0 : 0.0);
        premul = _VimsimVignetteColor.rgb * va;      // over the grains: head-fixed, on top
        alpha = 1.0 - (1.0 - grainAlpha) * (1.0 - va);
    }
    return float4(premul, alpha);
}

#ifndef VIMSIM_NO_TEST_ENTRY
// Test entry (CI, no Unity): one eye's image as vimsim's eye.frag lays it out. Pixel (i, j),
// row j from the top, has its centre at SV_Position (i + 0.5, j + 0.5); its ray on the plane
// z = 1 of the head frame is ((i + 0.5) / w * 2 - 1) tanHalf.x + offset.x, (1 - (j + 0.5) / h * 2)
// tanHalf.y + offset.y; the world ray follows from the head axes above.
cbuffer VimsimTest
{
    float4 _VimsimTestView;      // tan half width, tan half height, centre x, centre y (plane z = 1)
    float4 _VimsimTestSize;      // image width, height (pixels), 0, 0
};

float4 frag(float4 pos : SV_Position) : SV_Target
{
    float2 ij = pos.xy;
    float2 uv = float2((ij.x / _VimsimTestSize.x * 2.0 - 1.0) * _VimsimTestView.x + _VimsimTestView.z,
                       (1.0 - ij.y / _VimsimTestSize.y * 2.0) * _VimsimTestView.y + _VimsimTestView.w);
    float3 dHead = normalize(float3(uv, 1.0));
    float3 dWorld = normalize(dHead.x * _VimsimHeadRight.xyz + dHead.y * _VimsimHeadUp.xyz
                              + dHead.z * _VimsimHeadForward.xyz);
    float footprint = max(length(ddx(dHead)), length(ddy(dHead)));
    return VimsimOverlay(dWorld, dHead, footprint);
}
#endif
#endif
