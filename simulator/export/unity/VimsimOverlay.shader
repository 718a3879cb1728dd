// vimsim export: VimsimOverlay.shader, the mitigation overlay (grains, vignette, both) for the
// Built-in and Universal (URP) render pipelines; the drawing is VimsimOverlay.hlsl (shared, checked
// in vimsim's CI against vimsim render). Draw it on a sphere around the head (the prefab
// VimsimOverlay.prefab: Unity's sphere, culled front, positioned at the head every frame by
// VimsimEpofBehaviour), after the video (queue Overlay), premultiplied over it. Each pixel's ray
// is the direction from the eye to the sphere point, so both eyes (multi-pass, single-pass
// instanced) get their own rays. Parameters are set every frame by VimsimEpofBehaviour.
Shader "Vimsim/Overlay"
{
    Properties
    {
        [NoScaleOffset] _VimsimGrainMask ("Grain coverage (built at run time from the export)", 2D) = "black" {}
        // Set every frame by VimsimEpofBehaviour (declared so that the SRP batcher sees UnityPerMaterial whole).
        [HideInInspector] _VimsimHeadRight ("Head right", Vector) = (1, 0, 0, 0)
        [HideInInspector] _VimsimHeadUp ("Head up", Vector) = (0, 1, 0, 0)
        [HideInInspector] _VimsimHeadForward ("Head forward", Vector) = (0, 0, 1, 0)
        [HideInInspector] _VimsimCutout ("Cutout inner, outer (rad), grains on, opacity", Vector) = (0.314159, 0.698132, 1, 0)
        [HideInInspector] _VimsimVignette ("Vignette r_full, aperture_min / 2, feather (rad), on", Vector) = (1, 0.523599, 0.174533, 0)
        [HideInInspector] _VimsimVignetteColor ("Vignette colour", Color) = (0, 0, 0, 1)
        [HideInInspector] _VimsimMask ("Mask height, mips, yaw offset (rad)", Vector) = (2048, 0, 0, 0)
    }

    // Universal Render Pipeline
    SubShader
    {
        Tags { "RenderPipeline" = "UniversalPipeline" "Queue" = "Overlay" "RenderType" = "Transparent" "IgnoreProjector" = "True" }
        Pass
        {
            Name "VimsimOverlay"
            Blend One OneMinusSrcAlpha
            ZWrite Off
            ZTest Always
            Cull Front
            HLSLPROGRAM
            #pragma vertex VimsimVert
            #pragma fragment VimsimFrag
            #pragma target 3.0
            #pragma multi_compile_instancing
            #define VIMSIM_NO_TEST_ENTRY
            #include "Packages/com.unity.render-pipelines.universal/ShaderLibrary/Core.hlsl"
            #include "VimsimOverlay.hlsl"

            struct Attributes { float4 positionOS : POSITION; UNITY_VERTEX_INPUT_INSTANCE_ID };
            struct Varyings { float4 positionCS : SV_POSITION; float3 positionWS : TEXCOORD0; UNITY_VERTEX_OUTPUT_STEREO };

            Varyings VimsimVert(Attributes v)
            {
                Varyings o;
                UNITY_SETUP_INSTANCE_ID(v);
                UNITY_INITIALIZE_VERTEX_OUTPUT_STEREO(o);
                o.positionWS = TransformObjectToWorld(v.positionOS.xyz);
                o.positionCS = TransformWorldToHClip(o.positionWS);
                return o;
            }

            float4 VimsimFrag(Varyings i) : SV_Target
            {
                UNITY_SETUP_STEREO_EYE_INDEX_POST_VERTEX(i);
                float3 d = normalize(i.positionWS - GetCameraPositionWS());
                float3 dHead = VimsimToHead(d);
                float footprint = max(length(ddx(dHead)), length(ddy(dHead)));
                return VimsimOverlay(VimsimUnityToVideo(d), dHead, footprint);
            }
            ENDHLSL
        }
    }

    // Built-in render pipeline
    SubShader
    {
        Tags { "Queue" = "Overlay" "RenderType" = "Transparent" "IgnoreProjector" = "True" }
        Pass
        {
            Blend One OneMinusSrcAlpha
            ZWrite Off
            ZTest Always
            Cull Front
            CGPROGRAM
            #pragma vertex VimsimVert
            #pragma fragment VimsimFrag
            #pragma target 3.5
            #pragma multi_compile_instancing
            #define VIMSIM_NO_TEST_ENTRY
            #include "UnityCG.cginc"
            #include "VimsimOverlay.hlsl"

            struct Attributes { float4 vertex : POSITION; UNITY_VERTEX_INPUT_INSTANCE_ID };
            struct Varyings { float4 pos : SV_POSITION; float3 worldPos : TEXCOORD0; UNITY_VERTEX_OUTPUT_STEREO };

            Varyings VimsimVert(Attributes v)
            {
                Varyings o;
                UNITY_SETUP_INSTANCE_ID(v);
                UNITY_INITIALIZE_VERTEX_OUTPUT_STEREO(o);
                o.worldPos = mul(unity_ObjectToWorld, v.vertex).xyz;
                o.pos = UnityObjectToClipPos(v.vertex);
                return o;
            }

            float4 VimsimFrag(Varyings i) : SV_Target
            {
                UNITY_SETUP_STEREO_EYE_INDEX_POST_VERTEX(i);
                float3 d = normalize(i.worldPos - _WorldSpaceCameraPos);
                float3 dHead = VimsimToHead(d);
                float footprint = max(length(ddx(dHead)), length(ddy(dHead)));
                return VimsimOverlay(VimsimUnityToVideo(d), dHead, footprint);
            }
            ENDCG
        }
    }
}
