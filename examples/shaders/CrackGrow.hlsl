// Cracks that grow over time, in HLSL, for Unity Shader Graph (Custom Function node, File mode,
// name "CrackGrow") and Unreal (paste the body of CrackGrow_float into a Custom node).
//
// Inputs come from crackbake's packed data map (<stem>_CrackData.png for Unity targets,
// T_<stem>_Data.png for Unreal: R mask, G width, B depth, A time; import as linear/non-sRGB,
// uncompressed or BC7 to keep the 16-bit time smooth) and the target's normal map (Unity:
// OpenGL +Y, "Normal map" texture type; Unreal: DirectX -Y, TC_Normalmap, already unpacked to
// -1..1 by the sampler).  Animate Progress from 0 to 1.
//
// Unity Shader Graph wiring: Sample Texture 2D (data, Default/linear) -> Data; Sample Texture 2D
// (normal, Type Normal) -> NormalTS; the asset's clean albedo -> Albedo; outputs BaseColor ->
// Base Color, Normal -> Normal (Tangent Space), Occlusion -> Ambient Occlusion.
// Unreal Custom node: inputs Data (float4), Progress, Feather, Albedo (float3), CrackColor
// (float3), NormalTS (float3); output type CMOT Float4 returning float4(BaseColor, Open) and a
// second Custom node (or a Lerp) for the normal: lerp(float3(0,0,1), NormalTS, Grown).

float CrackGrowOpen(float4 Data, float Progress, float Feather)
{
    // Shared logic with examples/shaders/crack_grow.frag: open = mask where the front passed.
    float grown = saturate((Progress - Data.a) / max(Feather, 1e-4));
    return Data.r * grown;
}

void CrackGrow_float(float4 Data, float Progress, float Feather, float3 Albedo,
                     float3 CrackColor, float3 NormalTS, out float3 BaseColor,
                     out float3 Normal, out float Occlusion, out float Open)
{
    Open = CrackGrowOpen(Data, Progress, Feather);
    float grown = Data.r > 0.0 ? Open / Data.r : 0.0;
    BaseColor = lerp(Albedo, CrackColor, Open);
    Normal = normalize(lerp(float3(0.0, 0.0, 1.0), NormalTS, grown));
    Occlusion = 1.0 - 0.5 * Data.b * grown;
}

void CrackGrow_half(half4 Data, half Progress, half Feather, half3 Albedo, half3 CrackColor,
                    half3 NormalTS, out half3 BaseColor, out half3 Normal, out half Occlusion,
                    out half Open)
{
    float3 b, n; float o, op;
    CrackGrow_float(Data, Progress, Feather, Albedo, CrackColor, NormalTS, b, n, o, op);
    BaseColor = b; Normal = n; Occlusion = o; Open = op;
}
