import { createStore, type StoreApi } from 'zustand/vanilla';
import {
  noLimitText,
  breadcrumb,
  defaultOf,
  isValueNode,
  valuesEqual,
  type FormNode,
  type FormSchema,
  type FormValue,
  type ValueNode,
} from './ir';
import type { DraftStorage } from './storage';
import { validateValue } from './validate';

/**
 * The form model: server values (`base`), the user's unsaved edits, validation and server errors,
 * per-group error counts, conflicts. State lives in one zustand vanilla store; every field
 * component selects only its own slice (`edits[id]`, `base[id]`, `localErrors[id]`, …), so an
 * edit re-renders that field and the badges whose counts changed, nothing else.
 */

export interface Edit {
  value: FormValue;
  /** The server value when the edit was made: a different server value later is a conflict. */
  base: FormValue | undefined;
}

export interface Conflict {
  id: string;
  label: string;
  reason: string;
}

export interface Change {
  id: string;
  label: string;
  node: ValueNode;
  from: FormValue | undefined;
  to: FormValue;
}

export interface FormState {
  /** True once server values were loaded. */
  loaded: boolean;
  base: Record<string, FormValue>;
  edits: Record<string, Edit>;
  localErrors: Record<string, string>;
  /** Server errors by node id (a path may point at a group). */
  serverErrors: Record<string, string[]>;
  /** Server errors whose path matched nothing in the schema. */
  unplacedErrors: string[];
  /** Errors (local + server) inside each node, including the node itself. */
  errorCounts: Record<string, number>;
  conflicts: Conflict[];
  showExperimental: boolean;
  /** Active child per tabbed group ('' holds the active root section). */
  activeTab: Record<string, string>;
}

export interface FormModelOptions {
  storage?: DraftStorage;
  /** Storage key of this form's drafts (per machine); drafts carry the schema key inside. */
  storageKey?: string;
}

interface StoredDrafts {
  schemaKey: string;
  edits: Record<string, Edit>;
}

export function valueOf(s: FormState, schema: FormSchema, id: string): FormValue | undefined {
  const e = s.edits[id];
  if (e) return e.value;
  if (id in s.base) return s.base[id];
  const n = schema.nodes.get(id);
  return n ? defaultOf(n) : undefined;
}

export class FormModel {
  readonly store: StoreApi<FormState>;
  private readonly ancestorsOf = new Map<string, string[]>();
  /** For each node: the (variant id, child key) pairs that must be selected for it to be active. */
  private readonly branchOf = new Map<string, Array<[string, string]>>();
  private readonly storage: DraftStorage | undefined;
  private readonly storageKey: string | undefined;

  constructor(
    readonly schema: FormSchema,
    opts: FormModelOptions = {},
  ) {
    this.storage = opts.storage;
    this.storageKey = opts.storageKey;
    for (const [id, n] of schema.nodes) {
      const anc: string[] = [];
      const branch: Array<[string, string]> = [];
      let child: FormNode = n;
      let p = n.parent;
      while (p !== null) {
        anc.push(p);
        const pn = schema.nodes.get(p);
        if (!pn) break;
        if (pn.kind === 'variant') branch.push([pn.id, child.key]);
        child = pn;
        p = pn.parent;
      }
      this.ancestorsOf.set(id, anc);
      this.branchOf.set(id, branch);
    }
    this.store = createStore<FormState>(() => ({
      loaded: false,
      base: {},
      edits: {},
      localErrors: {},
      serverErrors: {},
      unplacedErrors: [],
      errorCounts: {},
      conflicts: [],
      showExperimental: false,
      activeTab: { '': schema.roots[0] ?? '' },
    }));
    this.restoreDrafts();
  }

  node(id: string): FormNode | undefined {
    return this.schema.nodes.get(id);
  }

  value(id: string): FormValue | undefined {
    return valueOf(this.store.getState(), this.schema, id);
  }

  ancestors(id: string): readonly string[] {
    return this.ancestorsOf.get(id) ?? [];
  }

  /** Whether the node is shown: its variant branches are selected, Present_When holds, experimental allowed. */
  isActive(id: string, s: FormState = this.store.getState()): boolean {
    for (const [variant, key] of this.branchOf.get(id) ?? []) {
      if (valueOf(s, this.schema, variant) !== key) return false;
    }
    for (const nid of [id, ...this.ancestors(id)]) {
      const n = this.schema.nodes.get(nid);
      if (!n) continue;
      if (n.experimental && !s.showExperimental) return false;
      if (n.presentWhen) {
        const v = valueOf(s, this.schema, n.presentWhen.field);
        if (!n.presentWhen.values.some((w) => valuesEqual(v, w))) return false;
      }
    }
    return true;
  }

  /** Load (or reload) the server values. Edits are kept; edits whose server value moved are conflicts. */
  setBase(values: Record<string, FormValue>): Conflict[] {
    const s = this.store.getState();
    const edits: Record<string, Edit> = {};
    const conflicts: Conflict[] = [];
    for (const [id, e] of Object.entries(s.edits)) {
      const now = values[id];
      if (valuesEqual(now, e.value)) continue; // the controller has what we wanted: nothing to send
      if (e.base !== undefined && !valuesEqual(now, e.base)) {
        conflicts.push({
          id,
          label: breadcrumb(this.schema, id),
          reason: `changed on the controller (was ${fmt(e.base)}, now ${fmt(now)}); your edit: ${fmt(e.value)}`,
        });
      }
      edits[id] = { value: e.value, base: now };
    }
    this.store.setState({
      loaded: true,
      base: values,
      edits,
      conflicts: [...s.conflicts.filter((c) => !conflicts.some((x) => x.id === c.id)), ...conflicts],
    });
    this.revalidateAll();
    this.persist();
    return conflicts;
  }

  set(id: string, value: FormValue): void {
    const n = this.schema.nodes.get(id);
    if (!n || !isValueNode(n)) return;
    const s = this.store.getState();
    const baseValue = id in s.base ? s.base[id] : undefined;
    const edits = { ...s.edits };
    if (baseValue !== undefined && valuesEqual(baseValue, value) && typeof baseValue === typeof value)
      delete edits[id];
    else edits[id] = { value, base: s.edits[id]?.base ?? baseValue };
    const err = validateValue(n, value, this.schema);
    const localErrors = updateRecord(s.localErrors, id, err);
    const patch: Partial<FormState> = { edits };
    if (localErrors !== s.localErrors) {
      patch.localErrors = localErrors;
      patch.errorCounts = this.countErrors(localErrors, s.serverErrors);
    }
    this.store.setState(patch);
    this.persist();
  }

  /** Back to the server value. */
  revert(id: string): void {
    const s = this.store.getState();
    if (!s.edits[id]) return;
    const edits = { ...s.edits };
    delete edits[id];
    const localErrors = updateRecord(s.localErrors, id, null);
    this.store.setState({ edits, localErrors, errorCounts: this.countErrors(localErrors, s.serverErrors) });
    this.persist();
  }

  /** To the schema default, when the controller sent one. */
  resetToDefault(id: string): boolean {
    const n = this.schema.nodes.get(id);
    const d = n ? defaultOf(n) : undefined;
    if (d === undefined) return false;
    this.set(id, d);
    return true;
  }

  discardAll(): void {
    const s = this.store.getState();
    this.store.setState({ edits: {}, localErrors: {}, errorCounts: this.countErrors({}, s.serverErrors) });
    this.persist();
  }

  setServerErrors(errors: ReadonlyArray<{ id: string | null; message: string }>): void {
    const serverErrors: Record<string, string[]> = {};
    const unplaced: string[] = [];
    for (const e of errors) {
      if (e.id === null || !this.schema.nodes.has(e.id)) unplaced.push(e.message);
      else (serverErrors[e.id] ??= []).push(e.message);
    }
    const s = this.store.getState();
    this.store.setState({
      serverErrors,
      unplacedErrors: unplaced,
      errorCounts: this.countErrors(s.localErrors, serverErrors),
    });
  }

  dismissConflicts(): void {
    this.store.setState({ conflicts: [] });
  }

  setShowExperimental(on: boolean): void {
    this.store.setState({ showExperimental: on });
  }

  setActiveTab(group: string, child: string): void {
    const s = this.store.getState();
    if (s.activeTab[group] === child) return;
    this.store.setState({ activeTab: { ...s.activeTab, [group]: child } });
  }

  /** Open every tab on the way to a node (search results, error links). */
  reveal(id: string): void {
    const chain = [id, ...this.ancestors(id)].reverse();
    const activeTab = { ...this.store.getState().activeTab };
    if (chain[0]) activeTab[''] = chain[0];
    for (let i = 0; i + 1 < chain.length; i++) {
      const g = this.schema.nodes.get(chain[i] as string);
      if (g?.kind === 'group' && g.tabbed) activeTab[g.id] = chain[i + 1] as string;
    }
    this.store.setState({ activeTab });
  }

  changes(): Change[] {
    const s = this.store.getState();
    const out: Change[] = [];
    for (const [id, e] of Object.entries(s.edits)) {
      const n = this.schema.nodes.get(id);
      if (!n || !isValueNode(n)) continue;
      // "1.20" typed over 1.2 is no change: keep the text in the field, send nothing.
      if (id in s.base && valuesEqual(s.base[id], e.value)) continue;
      out.push({ id, label: breadcrumb(this.schema, id), node: n, from: s.base[id], to: e.value });
    }
    return out;
  }

  hasLocalErrors(): boolean {
    return Object.keys(this.store.getState().localErrors).length > 0;
  }

  /** Search labels, ids and description text; returns value-node ids (at most `limit`). */
  search(query: string, limit = 60): string[] {
    const words = query.toLowerCase().split(/\s+/).filter(Boolean);
    if (words.length === 0) return [];
    const out: string[] = [];
    for (const [id, n] of this.schema.nodes) {
      if (n.kind === 'group') continue;
      const hay = `${n.label} ${breadcrumb(this.schema, id)} ${n.searchText}`.toLowerCase();
      if (words.every((w) => hay.includes(w))) {
        out.push(id);
        if (out.length >= limit) break;
      }
    }
    return out;
  }

  private revalidateAll(): void {
    const s = this.store.getState();
    const localErrors: Record<string, string> = {};
    for (const [id, e] of Object.entries(s.edits)) {
      const n = this.schema.nodes.get(id);
      if (!n || !isValueNode(n)) continue;
      const err = validateValue(n, e.value, this.schema);
      if (err) localErrors[id] = err;
    }
    this.store.setState({ localErrors, errorCounts: this.countErrors(localErrors, s.serverErrors) });
  }

  private countErrors(
    local: Record<string, string>,
    server: Record<string, string[]>,
  ): Record<string, number> {
    const counts: Record<string, number> = {};
    const add = (id: string) => {
      counts[id] = (counts[id] ?? 0) + 1;
      for (const a of this.ancestors(id)) counts[a] = (counts[a] ?? 0) + 1;
    };
    for (const id of Object.keys(local)) add(id);
    for (const [id, msgs] of Object.entries(server)) for (let i = 0; i < msgs.length; i++) add(id);
    return counts;
  }

  private persist(): void {
    if (!this.storage || !this.storageKey) return;
    const edits = this.store.getState().edits;
    if (Object.keys(edits).length === 0) this.storage.remove(this.storageKey);
    else
      this.storage.set(
        this.storageKey,
        JSON.stringify({ schemaKey: this.schema.key, edits } satisfies StoredDrafts),
      );
  }

  /** Unsaved edits from an earlier page (or schema). Edits the new schema cannot hold are conflicts. */
  private restoreDrafts(): void {
    if (!this.storage || !this.storageKey) return;
    const raw = this.storage.get(this.storageKey);
    if (!raw) return;
    let stored: StoredDrafts;
    try {
      stored = JSON.parse(raw) as StoredDrafts;
      if (!stored || typeof stored !== 'object' || typeof stored.edits !== 'object') return;
    } catch {
      return;
    }
    const edits: Record<string, Edit> = {};
    const conflicts: Conflict[] = [];
    for (const [id, e] of Object.entries(stored.edits)) {
      if (!e || typeof e !== 'object' || !isFormValue(e.value)) continue;
      const n = this.schema.nodes.get(id);
      if (!n || !isValueNode(n)) {
        conflicts.push({
          id,
          label: id.split('$').join(' › '),
          reason: `no longer exists; your edit ${fmt(e.value)} was dropped`,
        });
        continue;
      }
      if (stored.schemaKey !== this.schema.key && validateValue(n, e.value, this.schema)) {
        conflicts.push({
          id,
          label: breadcrumb(this.schema, id),
          reason: `the schema changed and your edit ${fmt(e.value)} no longer fits: ${validateValue(n, e.value, this.schema)}`,
        });
      }
      edits[id] = { value: e.value, base: isFormValue(e.base) ? e.base : undefined };
    }
    this.store.setState({ edits, conflicts });
    this.revalidateAll();
  }
}

function isFormValue(v: unknown): v is FormValue {
  if (typeof v === 'boolean' || typeof v === 'number' || typeof v === 'string') return true;
  return (
    typeof v === 'object' &&
    v !== null &&
    'numerator' in v &&
    'denominator' in v &&
    ['number', 'string'].includes(typeof v.numerator) &&
    ['number', 'string'].includes(typeof v.denominator)
  );
}

function updateRecord(r: Record<string, string>, id: string, err: string | null): Record<string, string> {
  if (err === null) {
    if (!(id in r)) return r;
    const n = { ...r };
    delete n[id];
    return n;
  }
  if (r[id] === err) return r;
  return { ...r, [id]: err };
}

export function fmt(v: FormValue | undefined): string {
  if (v === undefined) return '(none)';
  if (typeof v === 'object') return `${v.numerator} : ${v.denominator}`;
  if (typeof v === 'boolean') return v ? 'on' : 'off';
  if (typeof v === 'number') return noLimitText(v) ?? String(v);
  return v === '' ? '(empty)' : v;
}
