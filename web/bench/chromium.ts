// What the browser benches share: the psao binary they serve with, and the test browser
// (Debian's headless chromium with WebGL2 on SwiftShader, as `npm test`; CHROMIUM overrides
// /usr/bin/chromium) in a profile of its own that closing removes.
import { mkdtempSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { fileURLToPath } from "node:url";
import puppeteer, { type Browser } from "puppeteer-core";

/// The release binary (PSAO_BIN overrides). Bundled into build/bench/: the workspace's
/// target/ is three levels up.
export const BIN = process.env.PSAO_BIN ?? fileURLToPath(new URL("../../../target/release/psao", import.meta.url));

export const sleep = (ms: number) => new Promise((r) => setTimeout(r, ms));

/// A headless chromium and its temporary profile.
export interface HeadlessChromium {
  browser: Browser;
  /// Close the browser and remove its profile.
  close(): Promise<void>;
}

export async function launchChromium(): Promise<HeadlessChromium> {
  const profile = mkdtempSync(join(tmpdir(), "psao-chromium-"));
  const browser = await puppeteer.launch({
    executablePath: process.env.CHROMIUM ?? "/usr/bin/chromium",
    args: ["--headless", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", `--user-data-dir=${profile}`],
  });
  return {
    browser,
    close: async () => {
      await browser.close();
      rmSync(profile, { recursive: true, force: true });
    },
  };
}
