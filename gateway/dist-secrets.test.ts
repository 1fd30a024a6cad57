import { mkdtempSync, readdirSync, readFileSync, statSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { build } from 'vite';
import { describe, expect, it } from 'vitest';

function allFiles(dir: string): string[] {
  return readdirSync(dir).flatMap((f) => {
    const p = join(dir, f);
    return statSync(p).isDirectory() ? allFiles(p) : [p];
  });
}

describe('the built bundle', () => {
  it('contains no secret from the machines file or the environment', async () => {
    const dir = mkdtempSync(join(tmpdir(), 'shopdeck-dist-'));
    const machines = join(dir, 'machines.json');
    const literal = 'literal-duet-password-7f3a9c';
    const fromEnv = 'env-touchcut-key-91b2d4';
    writeFileSync(
      machines,
      JSON.stringify({
        machines: [
          {
            id: 'plasma-1',
            name: 'Plasma',
            kind: 'touchcut',
            url: 'https://kineticcutter',
            apiKey: 'env:SHOPDECK_TEST_TC_KEY',
          },
          { id: 'mk3', name: 'Printer', kind: 'duet', url: 'http://duet3.local', password: literal },
        ],
      }),
    );
    const outDir = join(dir, 'dist');
    const saved = { m: process.env.SHOPDECK_MACHINES, k: process.env.SHOPDECK_TEST_TC_KEY };
    process.env.SHOPDECK_MACHINES = machines;
    process.env.SHOPDECK_TEST_TC_KEY = fromEnv;
    try {
      await build({ logLevel: 'silent', build: { outDir, sourcemap: true, emptyOutDir: true } });
    } finally {
      if (saved.m === undefined) delete process.env.SHOPDECK_MACHINES;
      else process.env.SHOPDECK_MACHINES = saved.m;
      if (saved.k === undefined) delete process.env.SHOPDECK_TEST_TC_KEY;
      else process.env.SHOPDECK_TEST_TC_KEY = saved.k;
    }
    const files = allFiles(outDir);
    expect(files.some((f) => f.endsWith('.js'))).toBe(true);
    for (const f of files) {
      const text = readFileSync(f, 'utf8');
      expect(text.includes(literal), `${f} contains the Duet password`).toBe(false);
      expect(text.includes(fromEnv), `${f} contains the TouchCut key`).toBe(false);
      expect(text.includes('SHOPDECK_TEST_TC_KEY'), `${f} names the key's variable`).toBe(false);
    }
  }, 180_000);
});
