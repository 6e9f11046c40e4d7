// Screenshot of the web viewer in headless Chromium, for tests/test_viewer.py.
//   node tests/viewer_shot.mjs URL OUT.png WIDTH HEIGHT [CHROMIUM]
// Prints one JSON line: {"console": [{type, text}], "errors": [...], "ready": bool, "info": {...},
// "renderer": the WebGL renderer's name}.
// WebGL runs on SwiftShader (software), so it works on machines with no GPU.
import { createRequire } from 'node:module';

// playwright-core lives in viewer/node_modules, which this file's folder does not resolve.
const require = createRequire(new URL('../viewer/package.json', import.meta.url));
const { chromium } = require('playwright-core');

const [url, out, width, height, executablePath = '/usr/bin/chromium'] = process.argv.slice(2);
const browser = await chromium.launch({
  executablePath,
  headless: true,
  args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist', '--no-sandbox'],
});
const result = { console: [], errors: [], ready: false };
try {
  const page = await browser.newPage({ viewport: { width: Number(width), height: Number(height) }, deviceScaleFactor: 1 });
  page.on('console', (m) => result.console.push({ type: m.type(), text: m.text() }));
  page.on('pageerror', (e) => result.errors.push(`page error: ${e.message}`));
  page.on('requestfailed', (r) => result.errors.push(`request failed: ${r.url()} ${r.failure()?.errorText}`));
  page.on('response', (r) => { if (r.status() >= 400) result.errors.push(`HTTP ${r.status()}: ${r.url()}`); });
  await page.goto(url);
  await page.waitForFunction(() => window.viewerReady === true, null, { timeout: 60000 });
  result.ready = true;
  result.errors.push(...await page.evaluate(() => window.viewerErrors));
  result.info = await page.evaluate(() => window.viewerInfo);
  result.renderer = await page.evaluate(() => {
    const gl = document.createElement('canvas').getContext('webgl2');
    const info = gl && gl.getExtension('WEBGL_debug_renderer_info');
    return info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : null;
  });
  await page.screenshot({ path: out });
} catch (error) {
  result.errors.push(String(error));
} finally {
  await browser.close();
}
console.log(JSON.stringify(result));
process.exitCode = result.ready && !result.errors.length ? 0 : 1;
