// prt-view --window: an interactive SDL2 view of the relit pack (docs/viewer.md, "The window").
// Built into the prt-view executable only (the *_main.cpp name keeps it out of prt_viewer, so
// that the library never links SDL2).
//
// Each displayed frame: the environment rotated by the current drag angle is resampled and
// projected (only when the angle changed), relit with NWA, BI or PBI at the current budget (BI
// and PBI keep updating while the lighting is still, so they converge to the exact image, Overbeck
// et al. 2006 §5), shaded, rasterised from the orbiting camera and shown.
#include <SDL.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "runtime/per_band_incremental.h"
#include "viewer/environment_background.h"
#include "viewer/glossy_session.h"
#include "viewer/npy_writer.h"
#include "viewer/viewer_session.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/image_io.h"

namespace {

struct WindowState {
  double env_deg = 0;    // environment rotation about +Y
  double orbit_deg = 0;  // camera orbit about the target, about +Y
  std::size_t terms = 100;
  prt::LightingMode mode = prt::LightingMode::kPbi;
  bool exact = false;
};

// The drag angle in radians, as RunRotation converts its angles (viewer_session.cpp).
double Radians(double deg) {
  return deg * 3.14159265358979323846 / 180.0;
}

prt::Camera Orbit(const prt::Camera& c, double deg) {
  const double a = Radians(deg);
  const prt::Vec3 d = c.eye - c.target;
  prt::Camera out = c;
  out.eye = c.target + prt::Vec3{std::cos(a) * d.x + std::sin(a) * d.z, d.y,
                                 -std::sin(a) * d.x + std::cos(a) * d.z};
  return out;
}

// The window's frame as the user sees it (PNG, or .npy of its 8-bit codes), read back from the
// renderer (for the Xvfb test).
void SaveScreenshot(SDL_Renderer* renderer, const prt::Camera& camera, std::size_t bytes,
                    const std::string& screenshot) {
  std::vector<unsigned char> shot(bytes);
  if (SDL_RenderReadPixels(renderer, nullptr, SDL_PIXELFORMAT_RGB24, shot.data(),
                           3 * camera.width) != 0)
    return;
  if (screenshot.size() > 4 && screenshot.substr(screenshot.size() - 4) == ".npy") {
    const std::vector<float> codes(shot.begin(), shot.end());
    prt::WriteNpyFloat32(screenshot, codes, codes.size() / 3, 3);
  } else {
    prt::ImageRgb out(camera.width, camera.height);
    for (std::size_t i = 0; i < shot.size(); ++i)
      out.pixels[i] = static_cast<float>(prt::SrgbDecode(shot[i] / 255.0));
    prt::WritePng(out, screenshot);
  }
}

}  // namespace

int RunViewerWindow(const prt::ViewerSession& session,
                    const std::shared_ptr<const prt::EnvironmentLookup>& env,
                    const prt::Camera& camera, std::size_t terms, prt::LightingMode mode,
                    double exposure, int max_frames, const std::string& screenshot, bool exact) {
  if (SDL_Init(SDL_INIT_VIDEO) != 0)
    throw std::runtime_error(std::string("--window: SDL_Init failed: ") + SDL_GetError());
  struct Quit {
    ~Quit() { SDL_Quit(); }
  } quit;
  SDL_Window* window =
      SDL_CreateWindow("prt-view", SDL_WINDOWPOS_UNDEFINED, SDL_WINDOWPOS_UNDEFINED, camera.width,
                       camera.height, SDL_WINDOW_SHOWN);
  if (window == nullptr)
    throw std::runtime_error(std::string("--window: cannot open a window: ") + SDL_GetError());
  SDL_Renderer* renderer = SDL_CreateRenderer(window, -1, SDL_RENDERER_SOFTWARE);
  if (renderer == nullptr) renderer = SDL_CreateRenderer(window, -1, 0);
  if (renderer == nullptr)
    throw std::runtime_error(std::string("--window: no renderer: ") + SDL_GetError());
  SDL_Texture* texture = SDL_CreateTexture(
      renderer, SDL_PIXELFORMAT_RGB24, SDL_TEXTUREACCESS_STREAMING, camera.width, camera.height);

  const int n = session.cubemap_n();
  const std::size_t max_terms = 6u * static_cast<std::size_t>(n) * static_cast<std::size_t>(n);
  WindowState st;
  st.terms = std::min(terms, max_terms);
  st.mode = mode;
  st.exact = exact;
  const prt::ToneMapOptions tone{exposure, prt::ToneMap::kClamp};
  prt::CubemapRgb cube;
  prt::WaveletLighting lighting;
  prt::BackgroundFunction background;  // the environment image, rotated with the lighting
  double lit_deg = std::nan("");
  std::unique_ptr<prt::BasicIncrementalRelighter> bi;
  std::unique_ptr<prt::PerBandIncrementalRelighter> pbi;
  std::vector<unsigned char> rgb8(3 * static_cast<std::size_t>(camera.width) *
                                  static_cast<std::size_t>(camera.height));
  double fps = 0;
  bool running = true;
  for (int frame = 0; running && (max_frames <= 0 || frame < max_frames); ++frame) {
    const auto t0 = std::chrono::steady_clock::now();
    SDL_Event e;
    while (SDL_PollEvent(&e)) {
      if (e.type == SDL_QUIT) running = false;
      if (e.type == SDL_MOUSEMOTION && (e.motion.state & SDL_BUTTON_LMASK))
        st.env_deg += 0.5 * e.motion.xrel;
      if (e.type == SDL_MOUSEMOTION && (e.motion.state & SDL_BUTTON_RMASK))
        st.orbit_deg += 0.5 * e.motion.xrel;
      if (e.type == SDL_KEYDOWN) {
        switch (e.key.keysym.sym) {
          case SDLK_ESCAPE:
          case SDLK_q:
            running = false;
            break;
          case SDLK_n:
            st.mode = prt::LightingMode::kNwa;
            break;
          case SDLK_b:
            st.mode = prt::LightingMode::kBi;
            break;
          case SDLK_p:
            st.mode = prt::LightingMode::kPbi;
            break;
          case SDLK_e:
            st.exact = !st.exact;
            break;
          case SDLK_PLUS:
          case SDLK_EQUALS:
          case SDLK_KP_PLUS:
            st.terms = std::min(max_terms, 2 * st.terms);
            bi.reset();
            pbi.reset();
            break;
          case SDLK_MINUS:
          case SDLK_KP_MINUS:
            st.terms = std::max<std::size_t>(1, st.terms / 2);
            bi.reset();
            pbi.reset();
            break;
          default:
            break;
        }
      }
    }
    if (!(st.env_deg == lit_deg)) {
      cube = prt::ResampleToCubemap(env->image(), n, Radians(st.env_deg));
      lighting = prt::ProjectLighting(cube);
      background = prt::EnvironmentBackground(env, Radians(st.env_deg));
      lit_deg = st.env_deg;
    }
    prt::SampleRadiance radiance;
    if (st.exact) {
      radiance = session.RelightExact(lighting);
    } else if (st.mode == prt::LightingMode::kNwa) {
      radiance = prt::RelightApproximate(session.transport(), lighting, st.mode, st.terms);
    } else if (st.mode == prt::LightingMode::kBi) {
      if (!bi) {
        bi = std::make_unique<prt::BasicIncrementalRelighter>(session.transport(), n, st.terms);
        bi->Initialize(lighting);
      } else {
        bi->Update(lighting);
      }
      radiance = bi->Radiance();
    } else {
      if (!pbi) {
        pbi = std::make_unique<prt::PerBandIncrementalRelighter>(session.transport(), n, st.terms);
        pbi->Initialize(lighting);
      } else {
        pbi->Update(lighting);
      }
      radiance = pbi->Radiance();
    }
    // An image pack's view is fixed (its rows are the camera's pixels): no orbit. A glossy
    // pack's terms are combined for the orbiting eye (only the m-term sum per vertex).
    const prt::Camera view = session.image() != nullptr ? camera : Orbit(camera, st.orbit_deg);
    const prt::ImageRgb image = session.Render(view, session.Shade(radiance, view.eye), background);
    for (std::size_t i = 0; i < rgb8.size(); ++i) rgb8[i] = prt::ToSrgb8(image.pixels[i], tone);
    SDL_UpdateTexture(texture, nullptr, rgb8.data(), 3 * camera.width);
    SDL_RenderClear(renderer);
    SDL_RenderCopy(renderer, texture, nullptr, nullptr);
    if (!screenshot.empty() && (frame + 1 == max_frames || !running)) {
      // What the window shows, read back from the renderer (for the Xvfb test).
      std::vector<unsigned char> shot(rgb8.size());
      if (SDL_RenderReadPixels(renderer, nullptr, SDL_PIXELFORMAT_RGB24, shot.data(),
                               3 * camera.width) == 0) {
        if (screenshot.size() > 4 && screenshot.substr(screenshot.size() - 4) == ".npy") {
          // The 8-bit sRGB codes as float32, (width·height) × 3, row-major from the top-left.
          const std::vector<float> codes(shot.begin(), shot.end());
          prt::WriteNpyFloat32(screenshot, codes, codes.size() / 3, 3);
        } else {
          prt::ImageRgb out(camera.width, camera.height);
          for (std::size_t i = 0; i < shot.size(); ++i)
            out.pixels[i] = static_cast<float>(prt::SrgbDecode(shot[i] / 255.0));
          prt::WritePng(out, screenshot);
        }
      }
    }
    SDL_RenderPresent(renderer);
    const double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    fps = fps == 0 ? 1.0 / dt : 0.9 * fps + 0.1 / dt;
    char title[160];
    std::snprintf(title, sizeof title, "prt-view — %s — %zu terms — %.1f fps",
                  st.exact ? "exact" : prt::ToString(st.mode), st.terms, fps);
    SDL_SetWindowTitle(window, title);
  }
  SDL_DestroyTexture(texture);
  SDL_DestroyRenderer(renderer);
  SDL_DestroyWindow(window);
  return 0;
}

// The glossy asset in the window (docs/viewer.md, "Glossy assets"): left drag rotates the
// environment (block lighting recomputed), right drag orbits the camera (the view changes every
// vertex's BRDF: Algorithm 1 runs every frame), [ and ] scale every specular exponent by 1/2 or
// 2, r toggles the pixel-basis reference.
int RunGlossyWindow(prt::GlossySession& session,
                    const std::shared_ptr<const prt::EnvironmentLookup>& env,
                    const prt::Camera& camera, double exposure, int max_frames,
                    const std::string& screenshot, bool exact_cosine) {
  if (SDL_Init(SDL_INIT_VIDEO) != 0)
    throw std::runtime_error(std::string("--window: SDL_Init failed: ") + SDL_GetError());
  struct Quit {
    ~Quit() { SDL_Quit(); }
  } quit;
  SDL_Window* window =
      SDL_CreateWindow("prt-view (glossy)", SDL_WINDOWPOS_UNDEFINED, SDL_WINDOWPOS_UNDEFINED,
                       camera.width, camera.height, SDL_WINDOW_SHOWN);
  if (window == nullptr)
    throw std::runtime_error(std::string("--window: cannot open a window: ") + SDL_GetError());
  SDL_Renderer* renderer = SDL_CreateRenderer(window, -1, SDL_RENDERER_SOFTWARE);
  if (renderer == nullptr) renderer = SDL_CreateRenderer(window, -1, 0);
  if (renderer == nullptr)
    throw std::runtime_error(std::string("--window: no renderer: ") + SDL_GetError());
  SDL_Texture* texture = SDL_CreateTexture(
      renderer, SDL_PIXELFORMAT_RGB24, SDL_TEXTUREACCESS_STREAMING, camera.width, camera.height);

  const int n = session.cubemap_n();
  const prt::ToneMapOptions tone{exposure, prt::ToneMap::kClamp};
  double env_deg = 0, orbit_deg = 0, lit_deg = std::nan("");
  bool reference = false, lit_exact = false;
  // While the lighting is dragged it is resampled through the periodic grid (the runtime's
  // preview, vocabulary/cubemap_resample.h: ~1 ms instead of ~100 ms); on release exactly.
  const prt::PeriodicLatLongResampler preview(env->image(), n, 16 * n);
  prt::CubemapRgb cube;
  prt::BlockLighting light;
  prt::BackgroundFunction background;  // the environment image, rotated with the lighting
  std::vector<float> rgb(3 * session.sample_count());
  std::vector<unsigned char> rgb8(3 * static_cast<std::size_t>(camera.width) *
                                  static_cast<std::size_t>(camera.height));
  double fps = 0;
  bool running = true;
  for (int frame = 0; running && (max_frames <= 0 || frame < max_frames); ++frame) {
    const auto t0 = std::chrono::steady_clock::now();
    SDL_Event e;
    while (SDL_PollEvent(&e)) {
      if (e.type == SDL_QUIT) running = false;
      if (e.type == SDL_MOUSEMOTION && (e.motion.state & SDL_BUTTON_LMASK))
        env_deg += 0.5 * e.motion.xrel;
      if (e.type == SDL_MOUSEMOTION && (e.motion.state & SDL_BUTTON_RMASK))
        orbit_deg += 0.5 * e.motion.xrel;
      if (e.type == SDL_KEYDOWN) {
        const SDL_Keycode k = e.key.keysym.sym;
        if (k == SDLK_ESCAPE || k == SDLK_q) running = false;
        if (k == SDLK_r) reference = !reference;
        if (k == SDLK_LEFTBRACKET || k == SDLK_RIGHTBRACKET) {
          const double f = k == SDLK_RIGHTBRACKET ? 2.0 : 0.5;
          for (prt::Material& m : session.materials()) {
            m.exponent = std::clamp(m.exponent * f, 1.0, 1e4);
            m.exponent_v = std::clamp(m.exponent_v * f, 1.0, 1e4);
          }
        }
      }
    }
    const bool dragging = (SDL_GetMouseState(nullptr, nullptr) & SDL_BUTTON_LMASK) != 0;
    if (!(env_deg == lit_deg) || (!dragging && !lit_exact)) {
      cube = dragging ? preview.Resample(Radians(env_deg))
                      : prt::ResampleToCubemap(env->image(), n, Radians(env_deg));
      prt::UpdateBlockLighting(cube, session.blocks(), light);
      background = prt::EnvironmentBackground(env, Radians(env_deg));
      lit_deg = env_deg;
      lit_exact = !dragging;
    }
    const prt::Camera cam = Orbit(camera, orbit_deg);
    if (reference) {
      session.RelightReference(light, cam.eye, rgb);
    } else {
      session.Relight(light, cam.eye, rgb, {.exact_cosine = exact_cosine});
    }
    const prt::ImageRgb image = session.Render(cam, rgb, background);
    for (std::size_t i = 0; i < rgb8.size(); ++i) rgb8[i] = prt::ToSrgb8(image.pixels[i], tone);
    SDL_UpdateTexture(texture, nullptr, rgb8.data(), 3 * camera.width);
    SDL_RenderClear(renderer);
    SDL_RenderCopy(renderer, texture, nullptr, nullptr);
    if (!screenshot.empty() && (frame + 1 == max_frames || !running))
      SaveScreenshot(renderer, camera, rgb8.size(), screenshot);
    SDL_RenderPresent(renderer);
    const double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    fps = fps == 0 ? 1.0 / dt : 0.9 * fps + 0.1 / dt;
    char title[160];
    std::snprintf(title, sizeof title, "prt-view — glossy %s — %zu vertices — %.1f fps",
                  reference ? "pixel-basis reference" : "triple products", session.sample_count(),
                  fps);
    SDL_SetWindowTitle(window, title);
  }
  SDL_DestroyTexture(texture);
  SDL_DestroyRenderer(renderer);
  SDL_DestroyWindow(window);
  return 0;
}
