import { existsSync, readdirSync } from 'node:fs';
import { describe, expect, it } from 'vitest';
import { familiesOnDisk } from '../../scripts/bundle-report';
import { families } from './families';
import type { MachineKind } from '../fleet/types';
import { familyLabel, loadController, MACHINE_KINDS, MANIFESTS, manifestOf } from './index';

const folders = readdirSync(new URL('./', import.meta.url), { withFileTypes: true })
  .filter((d) => d.isDirectory())
  .map((d) => d.name);

describe('controller registry', () => {
  it('lists every family folder once, each by the manifest of its own kind', () => {
    expect([...MACHINE_KINDS].sort()).toEqual([...folders].sort());
    expect(new Set(MACHINE_KINDS).size).toBe(MACHINE_KINDS.length);
    expect(Object.keys(families).sort()).toEqual([...folders].sort());
    expect(manifestOf('no-such-family')).toBeUndefined();
  });

  it("loads every family's module on demand, of the right kind", async () => {
    for (const kind of MACHINE_KINDS) expect((await loadController(kind)).kind).toBe(kind);
    await expect(loadController('no-such-family' as MachineKind)).rejects.toThrow(/no-such-family/);
  });

  it("names each family as its declaration and its module do (the shell's labels need no family code)", async () => {
    for (const kind of MACHINE_KINDS) {
      expect(familyLabel(kind)).toBe(families[kind]?.label);
      expect((await loadController(kind)).label).toBe(familyLabel(kind));
      expect(families[kind]?.jobs).toEqual(manifestOf(kind)?.jobs);
    }
  });

  it("knows each family's first tab (views/Overview.tsx), for the bundle report's machine page", async () => {
    for (const { kind, firstTab } of familiesOnDisk()) {
      const first = (await loadController(kind as MachineKind)).tabs[0]?.Component as {
        preload?: () => Promise<unknown>;
      };
      expect(typeof first.preload, kind).toBe('function');
      const loaded = await first.preload?.();
      const expected: unknown = await import(/* @vite-ignore */ `../../${firstTab}`);
      expect(loaded, kind).toBe(expected);
    }
  });

  it("has a kiosk view where the family's manifest declares one: its views/KioskExtra.tsx", async () => {
    let extras = 0;
    for (const { kind, kioskExtra } of familiesOnDisk()) {
      const extra = manifestOf(kind)?.kiosk?.extra;
      expect(extra !== undefined, kind).toBe(kioskExtra !== null);
      if (!extra || !kioskExtra) continue;
      expect(existsSync(new URL(`../../${kioskExtra}`, import.meta.url))).toBe(true);
      const expected: unknown = await import(/* @vite-ignore */ `../../${kioskExtra}`);
      expect(await extra(), kind).toBe(expected);
      extras++;
    }
    expect(extras).toBeGreaterThan(0);
  });

  it("gives each family page a component, loaded from the family's folder when shown", async () => {
    const pages = MANIFESTS.flatMap((m) => m.pages ?? []);
    expect(pages.length).toBeGreaterThan(0);
    for (const p of pages) expect(typeof (await p.load())).toBe('function');
  });
});
