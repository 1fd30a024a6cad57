import { createContext, memo, useContext, useMemo, useState, type ReactNode } from 'react';
import { useStore } from 'zustand';
import { Badge, Button, Dialog, Notice } from '../ui';
import {
  breadcrumb,
  defaultOf,
  isValueNode,
  rangeText,
  valuesEqual,
  type FormNode,
  type FormValue,
  type RatioValue,
} from './ir';
import { fmt, valueOf, type FormModel } from './model';
import { sanitizeHtml } from './sanitize';
import './forms.css';

/**
 * The schema-driven form renderer. State lives in the FormModel's store; every component
 * selects only the slice it shows, so typing in one field re-renders that field (and a badge
 * when an error count changes), not the form.
 */

export interface FormViewProps {
  model: FormModel;
  /** Prefix for relative image sources in descriptions (the machine's `/machines/<id>`). */
  assetBase: string;
  readOnly?: boolean;
  /** Why it is read-only (shown once at the top). */
  readOnlyReason?: string;
}

export function FormView(props: FormViewProps) {
  const { model } = props;
  const [query, setQuery] = useState('');
  const hasExperimental = useMemo(
    () => [...model.schema.nodes.values()].some((n) => n.experimental),
    [model],
  );
  const showExperimental = useStore(model.store, (s) => s.showExperimental);
  const activeRoot = useStore(model.store, (s) => s.activeTab[''] ?? model.schema.roots[0] ?? '');
  const results = useMemo(() => (query.trim() ? model.search(query, 80) : null), [model, query]);
  return (
    <div className="fm" data-testid="form-view">
      <div className="fm-toolbar">
        <input
          className="ui-input fm-search"
          type="search"
          placeholder="Search settings and descriptions"
          aria-label="Search settings"
          value={query}
          onChange={(e) => setQuery(e.target.value)}
        />
        {hasExperimental && (
          <label className="fm-check">
            <input
              type="checkbox"
              checked={showExperimental}
              onChange={(e) => model.setShowExperimental(e.target.checked)}
            />
            Show experimental settings
          </label>
        )}
      </div>
      {props.readOnly && props.readOnlyReason && <Notice tone="info">{props.readOnlyReason}</Notice>}
      <Conflicts model={model} />
      <Unplaced model={model} />
      <FormContext.Provider value={{ model, assetBase: props.assetBase, readOnly: Boolean(props.readOnly) }}>
        {results ? (
          <div className="fm-results" data-testid="form-search-results">
            <p className="ui-muted" role="status">
              {results.length === 0
                ? 'No matching settings.'
                : `${results.length}${results.length >= 80 ? '+' : ''} matching settings`}
            </p>
            {results.map((id) => (
              <SearchHit
                key={id}
                id={id}
                onOpen={() => {
                  model.reveal(id);
                  setQuery('');
                }}
              />
            ))}
          </div>
        ) : (
          <div className="fm-body">
            <nav className="fm-sections" aria-label="Sections">
              {model.schema.roots.map((r) => (
                <SectionButton key={r} id={r} active={r === activeRoot} />
              ))}
            </nav>
            <div className="fm-section">{activeRoot && <NodeView id={activeRoot} depth={0} />}</div>
          </div>
        )}
      </FormContext.Provider>
    </div>
  );
}

// The form's context: its value never changes for a form, so it causes no re-renders.
interface Ctx {
  model: FormModel;
  assetBase: string;
  readOnly: boolean;
}
const FormContext = createContext<Ctx | null>(null);
function useForm(): Ctx {
  const c = useContext(FormContext);
  if (!c) throw new Error('FormView context missing');
  return c;
}

function ErrorBadge(props: { id: string }) {
  const { model } = useForm();
  const n = useStore(model.store, (s) => s.errorCounts[props.id] ?? 0);
  if (!n) return null;
  return (
    <Badge tone="bad" plain title={`${n} error${n === 1 ? '' : 's'} inside`} testId={`errors-${props.id}`}>
      {n}
    </Badge>
  );
}

function EditedBadge(props: { id: string }) {
  const { model } = useForm();
  const prefix = `${props.id}$`;
  const n = useStore(model.store, (s) => {
    let c = 0;
    for (const k in s.edits) if (k === props.id || k.startsWith(prefix)) c++;
    return c;
  });
  if (!n) return null;
  return (
    <Badge tone="info" plain title={`${n} unsaved edit${n === 1 ? '' : 's'}`}>
      ✎{n}
    </Badge>
  );
}

const SectionButton = memo(function SectionButton(props: { id: string; active: boolean }) {
  const { model } = useForm();
  const n = model.node(props.id);
  return (
    <button
      type="button"
      className={`fm-tab${props.active ? ' active' : ''}`}
      aria-current={props.active ? 'true' : undefined}
      onClick={() => model.setActiveTab('', props.id)}
      data-testid={`section-${props.id}`}
    >
      <span>{n?.label ?? props.id}</span>
      <ErrorBadge id={props.id} />
      <EditedBadge id={props.id} />
    </button>
  );
});

function useActive(id: string): boolean {
  const { model } = useForm();
  return useStore(model.store, (s) => model.isActive(id, s));
}

const NodeView = memo(function NodeView(props: { id: string; depth: number }) {
  const { model } = useForm();
  const n = model.node(props.id);
  const active = useActive(props.id);
  if (!n || !active) return null;
  if (n.kind === 'group') {
    // A section holding a single group of the same name (Prunt modules: "Fans" › "Fans") shows it directly.
    const only =
      props.depth === 0 && n.children.length === 1 ? model.node(n.children[0] as string) : undefined;
    if (only?.kind === 'group' && only.label === n.label) return <GroupView node={only} depth={0} />;
    return <GroupView node={n} depth={props.depth} />;
  }
  if (n.kind === 'variant') return <VariantView node={n} depth={props.depth} />;
  return <FieldRow id={n.id} />;
});

function GroupView(props: { node: Extract<FormNode, { kind: 'group' }>; depth: number }) {
  const { model } = useForm();
  const n = props.node;
  const activeChild = useStore(model.store, (s) => s.activeTab[n.id] ?? n.children[0] ?? '');
  const body = n.tabbed ? (
    <>
      <div className="fm-tabs" role="tablist" aria-label={n.label}>
        {n.children.map((c) => (
          <TabButton key={c} group={n.id} id={c} active={c === activeChild} />
        ))}
      </div>
      {activeChild && (
        <div role="tabpanel" className="fm-tabpanel">
          <NodeView id={activeChild} depth={props.depth + 1} />
        </div>
      )}
      {n.children.length === 0 && <p className="ui-muted">Nothing to configure here.</p>}
    </>
  ) : (
    <>
      {n.children.map((c) => (
        <NodeView key={c} id={c} depth={props.depth + 1} />
      ))}
      {n.children.length === 0 && <p className="ui-muted">Nothing to configure here.</p>}
    </>
  );
  if (props.depth === 0) {
    return (
      <div className="fm-root" data-testid={`group-${n.id}`}>
        <h3 className="fm-root-title">
          {n.label} <ErrorBadge id={n.id} />
        </h3>
        <Description html={n.description} />
        <ServerErrors id={n.id} />
        {body}
      </div>
    );
  }
  return (
    <fieldset className="fm-group" data-testid={`group-${n.id}`}>
      <legend>
        {n.label} <ErrorBadge id={n.id} />
      </legend>
      <Description html={n.description} />
      <ServerErrors id={n.id} />
      {body}
    </fieldset>
  );
}

function TabButton(props: { group: string; id: string; active: boolean }) {
  const { model } = useForm();
  const n = model.node(props.id);
  const active = useActive(props.id);
  if (!active) return null;
  return (
    <button
      type="button"
      role="tab"
      aria-selected={props.active}
      className={`fm-tab${props.active ? ' active' : ''}`}
      onClick={() => model.setActiveTab(props.group, props.id)}
      data-testid={`ftab-${props.id}`}
    >
      <span>{n?.label ?? props.id}</span>
      {n?.experimental && (
        <Badge tone="warn" plain>
          experimental
        </Badge>
      )}
      <ErrorBadge id={props.id} />
      <EditedBadge id={props.id} />
    </button>
  );
}

function VariantView(props: { node: Extract<FormNode, { kind: 'variant' }>; depth: number }) {
  const { model, readOnly } = useForm();
  const n = props.node;
  const value = useStore(model.store, (s) => valueOf(s, model.schema, n.id));
  const showExp = useStore(model.store, (s) => s.showExperimental);
  const selectedChild = n.children.find((c) => model.node(c)?.key === value);
  return (
    <fieldset className="fm-group fm-variant" data-testid={`variant-${n.id}`}>
      <legend>
        {n.label} <ErrorBadge id={n.id} />
      </legend>
      <Description html={n.description} />
      <div className="fm-row">
        <select
          className="ui-input fm-control"
          aria-label={n.label}
          value={typeof value === 'string' ? value : ''}
          disabled={readOnly}
          onChange={(e) => model.set(n.id, e.target.value)}
          data-testid={`field-${n.id}`}
        >
          {value === undefined && <option value="">—</option>}
          {n.children.map((c) => {
            const cn = model.node(c);
            if (!cn) return null;
            const exp = Boolean(cn.experimental);
            return (
              <option key={c} value={cn.key} disabled={exp && !showExp && cn.key !== value}>
                {cn.label}
                {exp ? ' (experimental)' : ''}
              </option>
            );
          })}
        </select>
        <FieldActions id={n.id} />
      </div>
      <p className="ui-muted fm-hint">The other choices keep their values and are sent too.</p>
      <FieldErrors id={n.id} />
      {selectedChild && <NodeView id={selectedChild} depth={props.depth + 1} />}
    </fieldset>
  );
}

function hasHelp(html: string): boolean {
  const t = html.trim();
  // Prunt sends "<p>None</p>" for some settings (an upstream quirk): no help to show.
  return t !== '' && t !== '<p>None</p>' && t !== 'None';
}

function Description(props: { html: string }) {
  const { assetBase } = useForm();
  const [open, setOpen] = useState(false);
  if (!hasHelp(props.html)) return null;
  return (
    <div className="fm-desc">
      <button type="button" className="fm-help" aria-expanded={open} onClick={() => setOpen(!open)}>
        {open ? 'Hide help' : 'Help'}
      </button>
      {open && <SanitizedHtml html={props.html.trim()} base={assetBase} />}
    </div>
  );
}

const SanitizedHtml = memo(function SanitizedHtml(props: { html: string; base: string }) {
  const clean = useMemo(() => sanitizeHtml(props.html, props.base), [props.html, props.base]);
  // Sanitized by DOMPurify just above: the only place controller HTML reaches the DOM.
  return <div className="fm-desc-body" dangerouslySetInnerHTML={{ __html: clean }} />;
});

function ServerErrors(props: { id: string }) {
  const { model } = useForm();
  const errs = useStore(model.store, (s) => s.serverErrors[props.id]);
  if (!errs?.length) return null;
  return (
    <div className="fm-error server" role="alert" data-testid={`server-error-${props.id}`}>
      {errs.map((e, i) => (
        <div key={i}>Controller: {e}</div>
      ))}
    </div>
  );
}

function FieldErrors(props: { id: string }) {
  const { model } = useForm();
  const local = useStore(model.store, (s) => s.localErrors[props.id]);
  return (
    <>
      {local && (
        <div className="fm-error" role="alert" data-testid={`local-error-${props.id}`}>
          {local}
        </div>
      )}
      <ServerErrors id={props.id} />
    </>
  );
}

function FieldActions(props: { id: string }) {
  const { model, readOnly } = useForm();
  const n = model.node(props.id);
  const edited = useStore(model.store, (s) => Boolean(s.edits[props.id]));
  const value = useStore(model.store, (s) => valueOf(s, model.schema, props.id));
  if (readOnly || !n) return null;
  const d = defaultOf(n);
  return (
    <span className="fm-actions">
      {edited && (
        <button
          type="button"
          className="fm-link"
          onClick={() => model.revert(props.id)}
          data-testid={`revert-${props.id}`}
        >
          Undo edit
        </button>
      )}
      {d !== undefined && !valuesEqual(d, value) && (
        <button
          type="button"
          className="fm-link"
          title={`Default: ${fmt(d)}`}
          onClick={() => model.resetToDefault(props.id)}
          data-testid={`default-${props.id}`}
        >
          Reset to default ({fmt(d)})
        </button>
      )}
    </span>
  );
}

function SearchHit(props: { id: string; onOpen: () => void }) {
  const { model } = useForm();
  return (
    <div className="fm-hit">
      <button type="button" className="fm-link" onClick={props.onOpen}>
        {breadcrumb(model.schema, props.id)}
      </button>
      {isValueNode(model.node(props.id) as FormNode) && model.node(props.id)?.kind !== 'variant' && (
        <FieldRow id={props.id} compact />
      )}
    </div>
  );
}

export const FieldRow = memo(function FieldRow(props: { id: string; compact?: boolean }) {
  const { model, readOnly, assetBase } = useForm();
  const [help, setHelp] = useState(false);
  const n = model.node(props.id);
  const value = useStore(model.store, (s) => valueOf(s, model.schema, props.id));
  const edited = useStore(model.store, (s) => Boolean(s.edits[props.id]));
  const hasError = useStore(model.store, (s) => Boolean(s.localErrors[props.id] || s.serverErrors[props.id]));
  if (!n) return null;
  const inputId = `fm-${props.id}`;
  let control: ReactNode;
  let hint: string | null = null;
  switch (n.kind) {
    case 'boolean':
      control = (
        <label className="fm-switch">
          <input
            id={inputId}
            type="checkbox"
            role="switch"
            checked={value === true}
            disabled={readOnly}
            onChange={(e) => model.set(n.id, e.target.checked)}
            data-testid={`field-${n.id}`}
          />
          <span>{value === true ? 'On' : 'Off'}</span>
        </label>
      );
      break;
    case 'discrete':
      control = (
        <select
          id={inputId}
          className="ui-input fm-control"
          value={typeof value === 'string' ? value : ''}
          disabled={readOnly}
          aria-invalid={hasError || undefined}
          onChange={(e) => model.set(n.id, e.target.value)}
          data-testid={`field-${n.id}`}
        >
          {typeof value !== 'string' && <option value="">—</option>}
          {n.options.map((o) => (
            <option key={o} value={o}>
              {o}
            </option>
          ))}
        </select>
      );
      break;
    case 'integer':
    case 'float':
      hint = `${n.kind === 'integer' ? 'whole number, ' : ''}${rangeText(n.min, n.max, n.unit)}`;
      control = (
        <span className="fm-num">
          <input
            id={inputId}
            className="ui-input fm-control"
            type="text"
            inputMode={n.kind === 'integer' ? 'numeric' : 'decimal'}
            autoComplete="off"
            value={numText(value)}
            disabled={readOnly}
            aria-invalid={hasError || undefined}
            onChange={(e) => model.set(n.id, e.target.value)}
            data-testid={`field-${n.id}`}
          />
          {n.unit && <span className="fm-unit">{n.unit}</span>}
        </span>
      );
      break;
    case 'ratio': {
      const r: RatioValue = typeof value === 'object' ? value : { numerator: '', denominator: '' };
      hint = `numerator : denominator, ratio ${rangeText(n.min, n.max)}`;
      control = (
        <span className="fm-ratio">
          <input
            id={inputId}
            className="ui-input fm-control"
            type="text"
            inputMode="decimal"
            aria-label={`${n.label}: numerator`}
            value={numText(r.numerator)}
            disabled={readOnly}
            aria-invalid={hasError || undefined}
            onChange={(e) => model.set(n.id, { numerator: e.target.value, denominator: r.denominator })}
            data-testid={`field-${n.id}-num`}
          />
          <span aria-hidden="true">:</span>
          <input
            className="ui-input fm-control"
            type="text"
            inputMode="decimal"
            aria-label={`${n.label}: denominator`}
            value={numText(r.denominator)}
            disabled={readOnly}
            aria-invalid={hasError || undefined}
            onChange={(e) => model.set(n.id, { numerator: r.numerator, denominator: e.target.value })}
            data-testid={`field-${n.id}-den`}
          />
        </span>
      );
      break;
    }
    case 'string':
      control = (
        <input
          id={inputId}
          className="ui-input fm-control"
          type="text"
          value={typeof value === 'string' ? value : ''}
          disabled={readOnly}
          aria-invalid={hasError || undefined}
          onChange={(e) => model.set(n.id, e.target.value)}
          data-testid={`field-${n.id}`}
        />
      );
      break;
    case 'unknown':
      control = <span className="ui-muted">unknown (raw {n.rawKind}): not editable here</span>;
      break;
    default:
      return null;
  }
  return (
    <div
      className={`fm-field${edited ? ' edited' : ''}${hasError ? ' invalid' : ''}`}
      data-testid={`row-${n.id}`}
    >
      <div className="fm-label">
        <label htmlFor={inputId}>{n.label}</label>
        {n.experimental && (
          <Badge tone="warn" plain>
            experimental
          </Badge>
        )}
        {edited && (
          <Badge tone="info" plain>
            edited
          </Badge>
        )}
        {!props.compact && hasHelp(n.description) && (
          <button type="button" className="fm-help" aria-expanded={help} onClick={() => setHelp(!help)}>
            {help ? 'Hide help' : 'Help'}
          </button>
        )}
      </div>
      <div className="fm-row">
        {control}
        <FieldActions id={n.id} />
      </div>
      {hint && <div className="fm-hint ui-muted">{hint}</div>}
      <FieldErrors id={n.id} />
      {help && <SanitizedHtml html={n.description.trim()} base={assetBase} />}
    </div>
  );
});

function numText(v: FormValue | undefined | number | string): string {
  if (v === undefined) return '';
  if (typeof v === 'number') return String(v);
  if (typeof v === 'string') return v;
  return '';
}

function Conflicts(props: { model: FormModel }) {
  const conflicts = useStore(props.model.store, (s) => s.conflicts);
  if (!conflicts.length) return null;
  return (
    <div className="ui-notice tone-warn" role="alert" data-testid="form-conflicts">
      <strong>
        {conflicts.length} unsaved edit{conflicts.length === 1 ? '' : 's'} conflict with the controller
      </strong>
      <ul>
        {conflicts.map((c) => (
          <li key={c.id}>
            <button type="button" className="fm-link" onClick={() => props.model.reveal(c.id)}>
              {c.label}
            </button>
            : {c.reason}
          </li>
        ))}
      </ul>
      <Button small onClick={() => props.model.dismissConflicts()}>
        Understood
      </Button>
    </div>
  );
}

function Unplaced(props: { model: FormModel }) {
  const errs = useStore(props.model.store, (s) => s.unplacedErrors);
  if (!errs.length) return null;
  return (
    <Notice tone="bad" title="The controller reports">
      {errs.join(' · ')}
    </Notice>
  );
}

/** "Review changes": every changed value, old → new, before anything is sent. */
export function ReviewChanges(props: {
  model: FormModel;
  onCancel: () => void;
  actions: ReactNode;
  note?: ReactNode;
}) {
  const edits = useStore(props.model.store, (s) => s.edits);
  const changes = useMemo(() => props.model.changes(), [props.model, edits]); // eslint-disable-line react-hooks/exhaustive-deps
  const errors = useStore(props.model.store, (s) => Object.keys(s.localErrors).length);
  return (
    <Dialog title="Review changes" onCancel={props.onCancel} actions={props.actions} testId="review-dialog">
      {changes.length === 0 ? (
        <p>No changes.</p>
      ) : (
        <table className="ui-table fm-review" data-testid="review-table">
          <thead>
            <tr>
              <th scope="col">Setting</th>
              <th scope="col">Now</th>
              <th scope="col">New</th>
            </tr>
          </thead>
          <tbody>
            {changes.map((c) => (
              <tr key={c.id}>
                <td>{c.label}</td>
                <td className="mono">{fmt(c.from)}</td>
                <td className="mono">
                  <strong>{fmt(c.to)}</strong>
                  {c.node.kind !== 'ratio' && c.node.kind !== 'boolean' && 'unit' in c.node && c.node.unit
                    ? ` ${c.node.unit}`
                    : ''}
                </td>
              </tr>
            ))}
          </tbody>
        </table>
      )}
      {errors > 0 && (
        <Notice tone="bad">
          {errors} value{errors === 1 ? ' is' : 's are'} invalid: fix {errors === 1 ? 'it' : 'them'} before
          saving.
        </Notice>
      )}
      {props.note}
    </Dialog>
  );
}
