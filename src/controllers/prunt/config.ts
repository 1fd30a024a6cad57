import type { StoreApi } from 'zustand/vanilla';
import { describeError, LinkError } from '../../fleet/errors';
import type { RunToken } from '../../fleet/kernel';
import { createSharedStore } from '../../fleet/kernel';
import type { MachineQueries } from '../../fleet/kernel';
import { isValueNode, valuesEqual } from '../../forms/ir';
import { FormModel } from '../../forms/model';
import type { DraftStorage } from '../../forms/storage';
import type { PruntClient } from './client';
import {
  buildFlatPatch,
  buildForm,
  buildModulePatch,
  placeErrors,
  readValues,
  type PruntApi,
} from './config-ir';
import { ALWAYS_FRESH, PRUNT_KEYS } from './queries';
import { initialConfigState, type ConfigState } from './state';

export interface PruntConfigDeps {
  machineId: string;
  client: PruntClient;
  queries: MachineQueries;
  drafts: DraftStorage;
  now: () => number;
  /** The session's current run: a read's answer is written only while the run that asked is current. */
  run: () => RunToken;
  /** The API generation the controller's status schema showed (null: not known yet). */
  api: () => PruntApi | null;
  /** The editor's store, made by the session (its views read it before this code is loaded). */
  store?: StoreApi<ConfigState>;
}

const API_WORDS: Record<PruntApi, string> = { module: 'module API', flat: 'flat API (2025)' };

function orphanWords(labels: string[]): string {
  const one = labels.length === 1;
  const named = labels.slice(0, 3).join(', ') + (labels.length > 3 ? ', …' : '');
  return `The controller's configuration schema changed and no longer holds ${one ? 'your unsaved edit' : `${labels.length} of your unsaved edits`} (${named}): discard ${one ? 'it' : 'them'} to load the new schema.`;
}

/**
 * The config editor's data: schema and values read on demand (when the editor opens, on
 * "Reload", after a server restart), a FormModel holding the user's drafts, and the save. The
 * values are never polled (nobody else edits them but a save, whose reply carries them).
 */
export class PruntConfig {
  readonly store: StoreApi<ConfigState>;
  private loading: { run: RunToken; done: Promise<void> } | null = null;
  private unwatch: (() => void) | null = null;

  constructor(private readonly deps: PruntConfigDeps) {
    this.store = deps.store ?? createSharedStore<ConfigState>(initialConfigState);
  }

  /** Open the editor: schema + values (once; again after a save or a server restart). */
  open(): Promise<void> {
    const c = this.store.getState();
    if (c.phase === 'ready') return Promise.resolve();
    // A load of a run that was stopped never finishes: a new run loads again.
    if (this.loading?.run.alive()) return this.loading.done;
    return this.load(null);
  }

  load(notice: string | null): Promise<void> {
    const run = this.deps.run();
    if (!run.alive()) return Promise.resolve();
    const done = this.read(run, notice).finally(() => {
      if (this.loading?.done === done) this.loading = null;
    });
    this.loading = { run, done };
    return done;
  }

  private async read(run: RunToken, notice: string | null): Promise<void> {
    const { client, queries } = this.deps;
    this.store.setState({ phase: 'loading', error: null });
    try {
      const { wire, text } = await queries.fetch(
        PRUNT_KEYS.configSchema,
        (signal) => client.configSchema(signal),
        ALWAYS_FRESH,
      );
      if (!run.alive()) return;
      // A server speaks one generation: a schema of the other is a broken answer, not a new form
      // (it would take the user's edits, whose ids it does not hold, and save the wrong shape).
      const api = this.deps.api();
      if (api && wire.api !== api)
        throw new LinkError(
          'protocol',
          `The config schema is of the ${API_WORDS[wire.api]}, but this controller speaks the ${API_WORDS[api]}`,
          { path: '(root)' },
        );
      const form = buildForm(wire, text);
      let { model } = this.store.getState();
      const old = this.store.getState().form;
      if (model && old && old.form.key !== form.form.key) {
        // A schema that cannot hold the user's unsaved edits does not replace the form: the
        // edits would be dropped. The user discards them first (then "Reload" takes it).
        const orphans = model.changes().filter((c) => {
          const n = form.form.nodes.get(c.id);
          return !n || !isValueNode(n);
        });
        if (orphans.length > 0) throw new Error(orphanWords(orphans.map((c) => c.label)));
      }
      if (!model || !old || old.form.key !== form.form.key) {
        model = new FormModel(form.form, {
          storage: this.deps.drafts,
          storageKey: `shopdeck:prunt:${this.deps.machineId}:drafts`,
        });
        this.watch(model);
        if (old && old.form.key !== form.form.key)
          notice = `${notice ?? ''} The configuration schema changed.`.trim();
      }
      this.store.setState({ form, model });
      const values = await queries.fetch(
        PRUNT_KEYS.configValues,
        (signal) => client.configValues(signal),
        ALWAYS_FRESH,
      );
      if (!run.alive()) return;
      const conflicts = model.setBase(readValues(form, values.Values));
      model.setServerErrors(placeErrors(form, values.Errors));
      if (conflicts.length)
        notice =
          `${notice ?? ''} ${conflicts.length} of your unsaved edits conflict with the controller's values.`.trim();
      this.store.setState({ phase: 'ready', notice });
    } catch (e) {
      if (run.alive()) this.store.setState({ phase: 'error', error: describeError(e) });
    }
  }

  /** Keeps `pending`/`invalid` in step with the model (what "Save" availability reads). */
  private watch(model: FormModel): void {
    this.unwatch?.();
    const sync = () =>
      this.store.setState({ pending: model.changes().length, invalid: model.hasLocalErrors() });
    sync();
    this.unwatch = model.store.subscribe(sync);
  }

  /** The Save command's work: only what changed; "saved or not" from the reply (README). */
  async save(commandId: string): Promise<string> {
    const { form, model } = this.store.getState();
    if (!form || !model) throw new Error('The configuration is not loaded');
    const changes = model.changes();
    if (changes.length === 0) throw new Error('Nothing to save');
    if (model.hasLocalErrors()) throw new Error('Fix the highlighted values first');
    const valueOf = (id: string) => model.value(id);
    const patch =
      form.api === 'flat' ? buildFlatPatch(form, changes, valueOf) : buildModulePatch(form, changes, valueOf);
    this.store.setState({ saving: true });
    try {
      const reply = await this.deps.client.saveConfig(patch, { commandId });
      const placed = placeErrors(form, reply.Errors);
      const newBase = readValues(form, reply.Values);
      const schemaError = placed.some((p) => p.schemaError);
      // The server answers 200 even when it rejects: a schema error means nothing was saved.
      // Without the flat API's message prefix, "saved" means the values came back as sent.
      const applied = changes.filter((c) => {
        const n = newBase[c.id];
        return n !== undefined && valuesEqual(n, c.to);
      }).length;
      const saved = !schemaError && (applied > 0 || changes.length === 0);
      model.setBase(newBase);
      model.setServerErrors(placed);
      const at = this.deps.now();
      if (!saved) {
        const message = `Nothing was saved: the controller rejected the change (${placed.length} error${placed.length === 1 ? '' : 's'} shown under the fields).`;
        this.store.setState({ lastSave: { at, saved: false, message } });
        throw new Error(message);
      }
      const message = placed.length
        ? `Saved ${applied} value${applied === 1 ? '' : 's'}; the controller reports ${placed.length} problem${placed.length === 1 ? '' : 's'} (shown under the fields).`
        : `Saved ${applied} value${applied === 1 ? '' : 's'}.`;
      this.store.setState({ lastSave: { at, saved: true, message }, offerReload: true });
      return message;
    } finally {
      this.store.setState({ saving: false });
    }
  }
}
