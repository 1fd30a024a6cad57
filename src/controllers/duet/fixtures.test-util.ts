import { readdirSync, readFileSync } from 'node:fs';
import { join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import type { JsonObject } from './patch';

/** Test helper: the verbatim fixtures in tests/fixtures/duet (Node only, never shipped). */
export const FIXTURES = resolve(fileURLToPath(new URL('.', import.meta.url)), '../../../tests/fixtures/duet');

export function fixtureText(rel: string): string {
  return readFileSync(join(FIXTURES, rel), 'utf8');
}

export function fixtureJson(rel: string): JsonObject {
  return JSON.parse(fixtureText(rel)) as JsonObject;
}

export function patchFiles(): string[] {
  const out: string[] = [];
  for (const dir of ['patches/dsf-python', 'patches/dsf-unittests']) {
    for (const f of readdirSync(join(FIXTURES, dir)).sort()) if (f.endsWith('.json')) out.push(`${dir}/${f}`);
  }
  return out;
}
