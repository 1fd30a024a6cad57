import { describe, expect, it } from 'vitest';
import type { FormNode, FormSchema } from './ir';
import { noLimitText, rangeText, toNumber } from './ir';
import { FormModel } from './model';
import { memoryDraftStorage } from './storage';
import { validateValue } from './validate';

function schema(key = 's1', extra: FormNode[] = []): FormSchema {
  const base = { description: '', searchText: '' };
  const nodes: FormNode[] = [
    {
      ...base,
      id: 'Motor',
      key: 'Motor',
      label: 'Motor',
      parent: null,
      kind: 'group',
      tabbed: true,
      children: ['Motor$A', 'Motor$B'],
    },
    {
      ...base,
      id: 'Motor$A',
      key: 'A',
      label: 'A',
      parent: 'Motor',
      kind: 'group',
      tabbed: false,
      children: ['Motor$A$Current', 'Motor$A$Steps', 'Motor$A$Mode'],
    },
    {
      ...base,
      id: 'Motor$A$Current',
      key: 'Current',
      label: 'Current',
      parent: 'Motor$A',
      kind: 'float',
      min: 0.125,
      max: 3,
      unit: 'amp',
      default: 1,
      searchText: 'run current of the coil',
    },
    {
      ...base,
      id: 'Motor$A$Steps',
      key: 'Steps',
      label: 'Steps',
      parent: 'Motor$A',
      kind: 'integer',
      min: 0,
      max: 15,
      unit: '',
    },
    {
      ...base,
      id: 'Motor$A$Mode',
      key: 'Mode',
      label: 'Mode',
      parent: 'Motor$A',
      kind: 'variant',
      children: ['Motor$A$Mode$Lead', 'Motor$A$Mode$Belt'],
      default: 'Lead',
    },
    {
      ...base,
      id: 'Motor$A$Mode$Lead',
      key: 'Lead',
      label: 'Lead',
      parent: 'Motor$A$Mode',
      kind: 'float',
      min: 1e-100,
      max: 1e100,
      unit: 'mm',
    },
    {
      ...base,
      id: 'Motor$A$Mode$Belt',
      key: 'Belt',
      label: 'Belt',
      parent: 'Motor$A$Mode',
      kind: 'ratio',
      min: 1e-100,
      max: 1e100,
    },
    {
      ...base,
      id: 'Motor$B',
      key: 'B',
      label: 'B',
      parent: 'Motor',
      kind: 'group',
      tabbed: false,
      children: ['Motor$B$Name'],
    },
    { ...base, id: 'Motor$B$Name', key: 'Name', label: 'Name', parent: 'Motor$B', kind: 'string' },
    ...extra,
  ];
  return { nodes: new Map(nodes.map((n) => [n.id, n])), roots: ['Motor'], key };
}

const BASE = {
  Motor$A$Current: 1.2,
  Motor$A$Steps: 4,
  Motor$A$Mode: 'Lead',
  Motor$A$Mode$Lead: 8,
  Motor$A$Mode$Belt: { numerator: 1, denominator: 1 },
  Motor$B$Name: 'x',
};

describe('validation', () => {
  const s = schema();
  const node = (id: string) => {
    const n = s.nodes.get(id);
    if (!n || n.kind === 'group' || n.kind === 'unknown') throw new Error(id);
    return n;
  };
  it('checks range, integers, ratios and required', () => {
    expect(validateValue(node('Motor$A$Current'), '3.5')).toMatch(/Out of range/);
    expect(validateValue(node('Motor$A$Current'), '2.5')).toBeNull();
    expect(validateValue(node('Motor$A$Current'), '')).toBe('Required');
    expect(validateValue(node('Motor$A$Current'), '1e')).toBe('Not a number');
    expect(validateValue(node('Motor$A$Steps'), '4.5')).toBe('Must be a whole number');
    expect(validateValue(node('Motor$A$Mode$Belt'), { numerator: 1, denominator: 0 })).toMatch(/denominator/);
    expect(validateValue(node('Motor$A$Mode$Belt'), { numerator: -1, denominator: 2 })).toMatch(
      /Ratio out of range/,
    );
    expect(validateValue(node('Motor$B$Name'), '  ')).toBe('Required');
    expect(validateValue(node('Motor$A$Mode'), 'Chain', s)).toMatch(/Choose/);
  });
  it('says "no limit" for ±1E100', () => {
    expect(rangeText(1e-100, 1e100)).toBe('> 0 · no upper limit');
    expect(rangeText(-1e100, 1e100)).toBe('no limit');
    expect(rangeText(0.125, 3, 'amp')).toBe('≥ 0.125 · ≤ 3 amp');
  });
});

describe('FormModel', () => {
  it('counts errors on every group up to the tab and the section', () => {
    const m = new FormModel(schema());
    m.setBase(BASE);
    m.set('Motor$A$Current', '9');
    m.set('Motor$A$Steps', '1.5');
    const s = m.store.getState();
    expect(s.errorCounts['Motor$A']).toBe(2);
    expect(s.errorCounts['Motor']).toBe(2);
    expect(s.errorCounts['Motor$B']).toBeUndefined();
    m.set('Motor$A$Current', '2');
    expect(m.store.getState().errorCounts['Motor$A']).toBe(1);
    m.setServerErrors([
      { id: 'Motor$B', message: 'group problem' },
      { id: null, message: 'somewhere' },
    ]);
    expect(m.store.getState().errorCounts['Motor']).toBe(2);
    expect(m.store.getState().unplacedErrors).toEqual(['somewhere']);
  });

  it('lists changes old → new, and "1.20" over 1.2 is no change', () => {
    const m = new FormModel(schema());
    m.setBase(BASE);
    m.set('Motor$A$Current', '1.20');
    expect(m.changes()).toEqual([]);
    m.set('Motor$A$Current', '2');
    expect(m.changes().map((c) => [c.label, c.from, c.to])).toEqual([['Motor › A › Current', 1.2, '2']]);
    m.revert('Motor$A$Current');
    expect(m.changes()).toEqual([]);
    expect(m.resetToDefault('Motor$A$Current')).toBe(true);
    expect(m.value('Motor$A$Current')).toBe(1);
    expect(m.resetToDefault('Motor$A$Steps')).toBe(false); // no default from the controller
  });

  it('keeps the other variant choices while switching', () => {
    const m = new FormModel(schema());
    m.setBase(BASE);
    m.set('Motor$A$Mode$Lead', '10');
    m.set('Motor$A$Mode', 'Belt');
    expect(m.isActive('Motor$A$Mode$Lead')).toBe(false);
    expect(m.isActive('Motor$A$Mode$Belt')).toBe(true);
    m.set('Motor$A$Mode', 'Lead');
    expect(m.value('Motor$A$Mode$Lead')).toBe('10');
  });

  it('keeps drafts across a page reload (same storage) and reports conflicts', () => {
    const storage = memoryDraftStorage();
    const opts = { storage, storageKey: 'drafts:m1' };
    const a = new FormModel(schema(), opts);
    a.setBase(BASE);
    a.set('Motor$A$Current', '2.5');
    a.set('Motor$A$Steps', '7');
    // "Page reload": a new model on the same storage, before the values arrive.
    const b = new FormModel(schema(), opts);
    expect(b.value('Motor$A$Current')).toBe('2.5');
    // The controller's value moved underneath an edit made on the old value: a conflict.
    const conflicts = b.setBase({ ...BASE, Motor$A$Steps: 9 });
    expect(conflicts.map((c) => c.id)).toEqual(['Motor$A$Steps']);
    expect(b.changes().length).toBe(2);
    const c2 = b.setBase({ ...BASE, Motor$A$Steps: 9, Motor$A$Current: 2.9 });
    expect(c2.map((c) => c.id)).toEqual(['Motor$A$Current']);
    expect(c2[0]?.reason).toMatch(/was 1.2, now 2.9/);
  });

  it('drops edits the controller already has', () => {
    const m = new FormModel(schema());
    m.setBase(BASE);
    m.set('Motor$A$Current', '2.5');
    m.setBase({ ...BASE, Motor$A$Current: 2.5 });
    expect(m.changes()).toEqual([]);
    expect(m.store.getState().conflicts).toEqual([]);
  });

  it('tells which drafts no longer fit a changed schema', () => {
    const storage = memoryDraftStorage();
    const a = new FormModel(schema('s1'), { storage, storageKey: 'k' });
    a.setBase(BASE);
    a.set('Motor$A$Steps', '12');
    a.set('Motor$B$Name', 'y');
    const s2 = schema('s2');
    const nodes = new Map(s2.nodes);
    nodes.set('Motor$A$Steps', {
      ...(nodes.get('Motor$A$Steps') as FormNode & { kind: 'integer' }),
      max: 10,
    });
    nodes.delete('Motor$B$Name');
    const b = new FormModel({ ...s2, nodes }, { storage, storageKey: 'k' });
    const c = b.store.getState().conflicts;
    expect(c.map((x) => x.id).sort()).toEqual(['Motor$A$Steps', 'Motor$B$Name']);
    expect(b.store.getState().localErrors['Motor$A$Steps']).toMatch(/Out of range/);
  });

  it('searches names and description text, and reveals the tabs on the way', () => {
    const m = new FormModel(schema());
    expect(m.search('coil')).toEqual(['Motor$A$Current']);
    expect(m.search('motor name')).toEqual(['Motor$B$Name']);
    m.reveal('Motor$B$Name');
    expect(m.store.getState().activeTab['Motor']).toBe('Motor$B');
  });

  it('an edit changes only that field and the counts', () => {
    const m = new FormModel(schema());
    m.setBase(BASE);
    const before = m.store.getState();
    m.set('Motor$A$Steps', '5');
    const after = m.store.getState();
    expect(after.base).toBe(before.base);
    expect(after.serverErrors).toBe(before.serverErrors);
    expect(after.localErrors).toBe(before.localErrors); // still valid: same object, no badge re-render
    expect(after.edits['Motor$A$Current']).toBe(before.edits['Motor$A$Current']);
  });
});

describe('Prunt\'s "no limit" values (±1E100)', () => {
  it('are words, not 1e+100, and the words read back as the number', () => {
    expect(noLimitText(1e100)).toBe('no limit');
    expect(noLimitText(-1e100)).toBe('no limit (negative)');
    expect(noLimitText(3)).toBeNull();
    expect(toNumber('no limit')).toBe(1e100);
    expect(toNumber(' No limit ')).toBe(1e100);
    expect(toNumber('no limit (negative)')).toBe(-1e100);
    expect(toNumber('2.5')).toBe(2.5);
    expect(rangeText(-1e100, 1e100)).toBe('no limit');
  });
});
