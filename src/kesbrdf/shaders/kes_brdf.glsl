// kesbrdf model evaluation in GLSL (the common subset of GLSL ES 3.00 and #version 410),
// exactly the recipe of docs/formats.md ("How to evaluate a model"). The one copy: the
// browser viewer's preview and GLSL check (viewer/src/shaders/kes_table.glsl puts it
// after its texture uniforms) and the BRDF Explorer export
// (kesbrdf.export.brdf_explorer.glsl_function puts it after its constant arrays).
//
// The host defines, before this text:
//   vec3 kesFetch(int i, int j)  q(phi_i, gamma_j) per channel, phi_i = i*2pi/kesNPhi,
//                                gamma_j = j*kesDGamma (texture or constant arrays)
//   int kesNPhi, kesNGamma; float kesDGamma;  the table's grid
//   vec3 kesBody               body term c in 1/sr
//   float kesBodyA, kesBodyP   its shape g(mu) = 1 - kesBodyA*(1 - mu)^kesBodyP, the body being
//                              c g(cos theta_i) g(cos theta_r) (eq. B3 of kesbrdf.models.body;
//                              kesBodyA = 0: Lambertian)
//   int kesMapping             0 deviation, 1 halfvector, 2 paper (eq. 3-4 literally)
//   float kesLambda            w = max(sqrt(cos_i cos_r), kesLambda*max(cos_i, cos_r)):
//                              0.5 "bounded", 0 "sqrtcos" (kesbrdf.models.mappings)
//   float kesGammaMax          last gamma of the table, radians
//   float kesFadeSlope         fade = clamp(1 - (gamma - kesGammaMax)*kesFadeSlope, 0, 1):
//                              1/6deg "fade", 0 "hold"
//   float kesLineSum           theta_i + theta_r of the fitted incidence line (paper mapping)
// as uniforms, constants or macros. Phi wraps periodically and gamma is clamped,
// exactly like the numpy lookup (kesbrdf.models.kes.lookup).

const float KES_PI = 3.141592653589793;
const float KES_TWO_PI = 6.283185307179586;
const float KES_GAMMA0_EPS = 1e-12;

// Bilinear lookup of q at (phi, gamma): periodic in phi, clamped in gamma.
vec3 kesLookup(float phi, float gamma) {
  float u = mod(phi, KES_TWO_PI) / KES_TWO_PI * float(kesNPhi);
  float u0 = floor(u);
  float fu = u - u0;
  int i0 = int(u0) % kesNPhi;
  int i1 = (i0 + 1) % kesNPhi;
  float v = clamp(gamma / kesDGamma, 0.0, float(kesNGamma - 1));
  float v0 = floor(v);
  float fv = v - v0;
  int j0 = min(int(v0), kesNGamma - 1);
  int j1 = min(j0 + 1, kesNGamma - 1);
  vec3 a = mix(kesFetch(i0, j0), kesFetch(i0, j1), fv);
  vec3 b = mix(kesFetch(i1, j0), kesFetch(i1, j1), fv);
  return mix(a, b, fu);
}

// (phi, gamma) of a pair for the deviation (0) or halfvector (1) mapping.
void kesPhiGamma(vec3 wi, vec3 wr, out float phi, out float gamma) {
  vec2 s;
  if (kesMapping == 0) {
    vec3 m = vec3(-wi.xy, wi.z);
    gamma = atan(length(cross(wr, m)), dot(wr, m));
    s = wi.xy + wr.xy;
  } else {
    vec3 h = normalize(wi + wr);
    gamma = 2.0 * atan(length(h.xy), h.z);
    s = h.xy;
  }
  // at the mirror direction: the plane of incidence
  if (length(s) < KES_GAMMA0_EPS) s = wr.xy - wi.xy;
  phi = atan(s.y, s.x);
}

// The body's factor g(cos_i) g(cos_r) (kesbrdf.models.body.BodyLaw); 1 for a Lambertian body.
float kesBodyG(float mu) {
  return 1.0 - kesBodyA * pow(clamp(1.0 - mu, 0.0, 1.0), kesBodyP);
}
float kesBodyShape(float cosI, float cosR) {
  return kesBodyA == 0.0 ? 1.0 : kesBodyG(cosI) * kesBodyG(cosR);
}

// Foreshortening weight w of f_r = c + fade*q/w (kesbrdf.models.mappings.foreshortening).
float kesWeight(float cosI, float cosR) {
  return max(sqrt(cosI * cosR), kesLambda * max(cosI, cosR));
}

// The lobe's factor beyond the last measured gamma (kesbrdf.models.mappings.fade); 1 for "hold".
float kesFade(float gamma) {
  return clamp(1.0 - (gamma - kesGammaMax) * kesFadeSlope, 0.0, 1.0);
}

// sqrt(cos_i cos_r) / w on the incidence line theta_i + theta_r = kesLineSum at |gamma|
// (kesbrdf.models.mappings.line_foreshortening); 1 for "sqrtcos".
float kesLineRatio(float g) {
  if (kesLambda == 0.0) return 1.0;
  float geo = sqrt(max((cos(g) + cos(kesLineSum)) / 2.0, 0.0));
  float cosHi = cos(clamp((kesLineSum - g) / 2.0, 0.0, 0.5 * KES_PI));
  return geo / max(geo, kesLambda * cosHi);
}

// paper eq. 3-4 literally, as kesbrdf.models.kes does it: rho_KES = q*kesLineRatio + body*sqrt(cos(gamma)/2)
// (the measured quantity on the theta_i + theta_r = 90 deg line), divided by
// sqrt(cos theta_i cos theta_r) * sin(beta), sin(beta) clamped at KES_PAPER_MIN_SIN_BETA.
const float KES_PAPER_MIN_SIN_BETA = 1e-6;
vec3 kesPaper(vec3 wi, vec3 wr) {
  float thetaI = atan(length(wi.xy), wi.z);
  float thetaR = atan(length(wr.xy), wr.z);
  float phiI = atan(wi.y, wi.x);
  float phiR = atan(wr.y, wr.x);
  float phi = 0.5 * KES_PI - (phiI + phiR);
  float gamma = thetaR - thetaI;
  if (gamma < 0.0) phi += KES_PI;  // (phi, gamma < 0) is the deviation toward phi + pi
  float s = sin(phiR - phiI - KES_PI);
  float c = cos(thetaR);
  float sinHalfBeta = clamp(0.5 * sqrt(s * s + c * c), 0.0, 1.0);
  float sinBeta = max(sin(2.0 * asin(sinHalfBeta)), KES_PAPER_MIN_SIN_BETA);
  float g = abs(gamma);
  float bodyLine = kesBodyShape(cos((kesLineSum - g) / 2.0), cos((kesLineSum + g) / 2.0));
  vec3 rho = kesLookup(phi, g) * kesLineRatio(g) + kesBody * (sqrt(max(cos(gamma), 0.0) / 2.0) * bodyLine);
  return rho / (sqrt(wi.z * wr.z) * sinBeta);
}

// f_r = c g(cos_i) g(cos_r) + fade(gamma)*q/w in 1/sr per channel; zero at or below the horizon.
vec3 kesBRDF(vec3 wi, vec3 wr) {
  if (wi.z <= 0.0 || wr.z <= 0.0) return vec3(0.0);
  if (kesMapping == 2) return kesPaper(wi, wr);
  float phi;
  float gamma;
  kesPhiGamma(wi, wr, phi, gamma);
  return kesBody * kesBodyShape(wi.z, wr.z) + kesLookup(phi, gamma) * (kesFade(gamma) / kesWeight(wi.z, wr.z));
}
