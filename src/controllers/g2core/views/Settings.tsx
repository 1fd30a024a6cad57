import { useState } from 'react';
import { describeError } from '../../../fleet/errors';
import { CommandButton, useStoreSelect } from '../../../fleet/react';
import { Button, EmptyState, Notice, Panel } from '../../../ui';
import { useSettingsGroup, useSettingsGroups } from '../queries';
import type { G2coreSession } from '../session';
import { SECTION_ORDER, groupKind, groupTitle, keyMeta, parseInput, type KeyMeta } from '../settings-meta';
import type { Scalar } from '../wire';

/** The machine tree browsed from `GET /machine?shallow=true`; each group a form (supervisor). */
export function SettingsTab({ session }: { session: G2coreSession }) {
  // On-demand reads through the query layer (queries.ts): cached per machine, stale after a while.
  const list = useSettingsGroups(session);
  const groups = list.data ?? null;
  const groupsError = list.error ? describeError(list.error) : null;
  const [selected, setSelected] = useState<string>('x');

  return (
    <div className="g2-settings" data-testid="g2-settings">
      <Panel title="Groups">
        {groupsError && (
          <Notice tone="bad" title="Could not list the machine's groups">
            {groupsError}
          </Notice>
        )}
        {groups === null && !groupsError && <span className="ui-muted">Loading…</span>}
        <nav className="g2-groups" aria-label="Settings groups">
          {groups &&
            SECTION_ORDER.map((sec) => {
              const list = groups.filter((g) => groupKind(g) === sec.kind);
              if (list.length === 0) return null;
              return (
                <div key={sec.kind}>
                  <h3>{sec.title}</h3>
                  {list.map((g) => (
                    <Button
                      key={g}
                      aria-current={g === selected}
                      onClick={() => setSelected(g)}
                      data-testid={`g2-group-${g}`}
                    >
                      {groupTitle(g)}
                    </Button>
                  ))}
                </div>
              );
            })}
        </nav>
      </Panel>
      <GroupForm session={session} group={selected} />
    </div>
  );
}

function GroupForm({ session, group }: { session: G2coreSession; group: string }) {
  // A settings write makes the group stale (the command's `invalidates`): it is read again.
  const read = useSettingsGroup(session, group);
  const values = read.data;
  const loading = read.fetching;
  const error = read.error ? describeError(read.error) : null;
  return (
    <Panel
      title={`${groupTitle(group)} (${group})`}
      actions={
        <Button onClick={read.refetch} busy={loading}>
          Reload
        </Button>
      }
      testId={`g2-form-${group}`}
    >
      {error && (
        <Notice tone="bad" title="Could not read this group">
          {error}
        </Notice>
      )}
      {!values && !error && <EmptyState>{loading ? 'Loading…' : 'No values.'}</EmptyState>}
      {values &&
        Object.entries(values).map(([key, v]) => (
          <FieldRow
            key={`${group}.${key}:${JSON.stringify(v)}`}
            session={session}
            group={group}
            k={key}
            current={v}
          />
        ))}
      {session.machine.simulated && (
        <p className="ui-muted">Simulated controller: settings live in the simulator only.</p>
      )}
    </Panel>
  );
}

function FieldRow(props: { session: G2coreSession; group: string; k: string; current: Scalar }) {
  const { session, group, k, current } = props;
  const field = `${group}.${k}`;
  const meta = keyMeta(group, k);
  const { refused, fieldError, saved } = useStoreSelect(session.settings, (s) => ({
    refused: Boolean(s.refusedReadOnly[field]),
    fieldError: s.fieldErrors[field],
    saved: s.saved[field],
  }));
  const readOnly = Boolean(meta?.readOnly) || refused;
  const [draft, setDraft] = useState(current === null ? '' : String(current));
  const parsed = parseInput(meta, current, draft);
  const changed = 'value' in parsed && parsed.value !== current;
  const id = `g2-field-${group}-${k}`;
  const { commands: runner, snapshot } = session.ctx;
  return (
    <div className="g2-field" data-testid={`g2-field-${field}`}>
      <div>
        <label htmlFor={id}>
          <strong>{meta?.name ?? k}</strong>{' '}
          <span className="key">{group === 'sys' ? k : `${group}${k}`}</span>
          {meta?.unit ? <span className="ui-muted"> ({meta.unit})</span> : null}
        </label>
        {meta && <div className="desc">{meta.description}</div>}
      </div>
      <div>
        {readOnly ? (
          <div id={id} data-testid={`g2-value-${field}`}>
            <span className="mono">{current === null ? '—' : optionWords(meta, current)}</span>{' '}
            <span className="ui-muted" data-testid={`g2-readonly-${field}`}>
              (read-only)
            </span>
          </div>
        ) : (
          <Input
            id={id}
            meta={meta}
            current={current}
            draft={draft}
            setDraft={setDraft}
            invalid={'error' in parsed}
          />
        )}
      </div>
      <div>
        {!readOnly &&
          ('value' in parsed ? (
            <CommandButton
              runner={runner}
              snapshot={snapshot}
              command={session.setSetting}
              args={{ group, key: k, value: parsed.value }}
              variant={changed ? 'primary' : 'secondary'}
              testId={`g2-save-${field}`}
            >
              Save
            </CommandButton>
          ) : (
            <span className="ui-muted">{parsed.error}</span>
          ))}
        {saved && !fieldError && <span className="ok"> saved</span>}
      </div>
      {fieldError && (
        <div className="err" role="alert" data-testid={`g2-error-${field}`}>
          Refused by the controller: {fieldError}
        </div>
      )}
    </div>
  );
}

function optionWords(meta: KeyMeta | null, v: Scalar): string {
  if (meta?.options && typeof v === 'number') return meta.options[v] ?? `unknown (raw ${v})`;
  return String(v);
}

function Input(props: {
  id: string;
  meta: KeyMeta | null;
  current: Scalar;
  draft: string;
  setDraft: (s: string) => void;
  invalid: boolean;
}) {
  const { id, meta, current, draft, setDraft } = props;
  if ((meta?.kind === 'enum' || meta?.kind === 'flag') && meta.options) {
    const opts = Object.entries(meta.options).map(([v, words]) => [v, `${words} (${v})`] as const);
    if (!opts.some(([v]) => v === draft)) opts.push([draft, `unknown (raw ${draft})`]);
    return (
      <select id={id} className="ui-input" value={draft} onChange={(e) => setDraft(e.target.value)}>
        {opts.map(([v, words]) => (
          <option key={v} value={v}>
            {words}
          </option>
        ))}
      </select>
    );
  }
  if (meta?.kind === 'boolean' || typeof current === 'boolean') {
    return (
      <select id={id} className="ui-input" value={draft} onChange={(e) => setDraft(e.target.value)}>
        <option value="true">true</option>
        <option value="false">false</option>
      </select>
    );
  }
  const numeric = meta ? meta.kind !== 'text' : typeof current === 'number';
  return (
    <input
      id={id}
      className="ui-input"
      inputMode={numeric ? 'decimal' : 'text'}
      value={draft}
      aria-invalid={props.invalid}
      onChange={(e) => setDraft(e.target.value)}
      data-testid={`g2-input-${id.slice('g2-field-'.length)}`}
    />
  );
}
