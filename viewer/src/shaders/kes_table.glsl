// The viewer's table source for the shared model evaluation
// (src/kesbrdf/shaders/kes_brdf.glsl, which follows this text in every shader): the
// preview and the GLSL-Python agreement test both run it, so the test checks the code
// the preview runs.
//
// kesTable: RGBA32F texture, width n_phi (texel i = phi_i = i*2pi/n_phi), height
// n_gamma (texel j = gamma_j = j*dGamma). Filtering is done here by hand with
// texelFetch: phi wraps periodically, gamma is clamped, exactly like the numpy lookup.
uniform highp sampler2D kesTable;
uniform int kesNPhi;
uniform int kesNGamma;
uniform float kesDGamma;
uniform vec3 kesBody;     // body term c in 1/sr (model's, or base_color/pi for a colourway)
uniform float kesBodyA;   // the body's shape g(mu) = 1 - kesBodyA*(1 - mu)^kesBodyP (body_law; 0: Lambertian)
uniform float kesBodyP;
uniform int kesMapping;   // 0 deviation, 1 halfvector, 2 paper (eq. 3-4 literally)
// The model file's parameters (docs/formats.md steps 2-3; model.ts KesModel):
uniform float kesLambda;    // w = max(sqrt(cos_i cos_r), kesLambda*max(cos_i, cos_r)): 0.5 "bounded", 0 "sqrtcos"
uniform float kesGammaMax;  // last gamma of the table, radians
uniform float kesFadeSlope; // fade = clamp(1 - (gamma - kesGammaMax)*kesFadeSlope, 0, 1): 1/6deg "fade", 0 "hold"
uniform float kesLineSum;   // theta_i + theta_r of the fitted incidence line, radians (paper mapping)

vec3 kesFetch(int i, int j) {
  return texelFetch(kesTable, ivec2(i, j), 0).rgb;
}
