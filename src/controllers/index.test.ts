import { describe, expect, it } from 'vitest';
import { FIRST_TAB_VIEWS } from '../../scripts/bundle-report';
import { MACHINE_KINDS } from '../fleet/types';
import { families } from './families';
import { FAMILY_LABELS, loadController } from './index';

describe('controller registry', () => {
  it("loads every family's module on demand, of the right kind", async () => {
    for (const kind of MACHINE_KINDS) expect((await loadController(kind)).kind).toBe(kind);
  });

  it("names each family as its declaration does (the shell's labels need no family code)", () => {
    for (const kind of MACHINE_KINDS) expect(FAMILY_LABELS[kind]).toBe(families[kind].label);
  });

  it("knows each family's first tab, for the bundle report's machine page", async () => {
    for (const kind of MACHINE_KINDS) {
      const first = (await loadController(kind)).tabs[0]?.Component as { preload?: () => Promise<unknown> };
      expect(typeof first.preload, kind).toBe('function');
      const loaded = await first.preload?.();
      const expected: unknown = await import(/* @vite-ignore */ `../../${FIRST_TAB_VIEWS[kind]}`);
      expect(loaded, kind).toBe(expected);
    }
  });
});
