import { useEffect, useId, useRef, type ButtonHTMLAttributes, type ReactNode } from 'react';

export type Tone = 'ok' | 'warn' | 'bad' | 'info' | 'muted' | 'paused';

export function Panel(props: {
  title?: ReactNode;
  actions?: ReactNode;
  children: ReactNode;
  className?: string;
  testId?: string;
}) {
  return (
    <section className={`ui-panel ${props.className ?? ''}`} data-testid={props.testId}>
      {(props.title || props.actions) && (
        <header>
          {props.title ? <h2>{props.title}</h2> : <span />}
          {props.actions && <div className="ui-row">{props.actions}</div>}
        </header>
      )}
      {props.children}
    </section>
  );
}

export function KeyValues(props: { items: Array<[ReactNode, ReactNode]>; testId?: string }) {
  return (
    <dl className="ui-kv" data-testid={props.testId}>
      {props.items.map(([k, v], i) => (
        <div key={i} style={{ display: 'contents' }}>
          <dt>{k}</dt>
          <dd>{v ?? '—'}</dd>
        </div>
      ))}
    </dl>
  );
}

export interface Column<T> {
  key: string;
  label: ReactNode;
  render?: (row: T) => ReactNode;
  align?: 'left' | 'right';
}

export function DataTable<T>(props: {
  columns: Column<T>[];
  rows: readonly T[];
  rowKey: (row: T, index: number) => string;
  empty?: ReactNode;
  caption?: ReactNode;
  testId?: string;
}) {
  if (props.rows.length === 0) return <EmptyState>{props.empty ?? 'Nothing to show.'}</EmptyState>;
  return (
    <div className="ui-table-wrap">
      <table className="ui-table" data-testid={props.testId}>
        {props.caption && <caption className="ui-muted">{props.caption}</caption>}
        <thead>
          <tr>
            {props.columns.map((c) => (
              <th key={c.key} className={c.align === 'right' ? 'num' : undefined} scope="col">
                {c.label}
              </th>
            ))}
          </tr>
        </thead>
        <tbody>
          {props.rows.map((r, i) => (
            <tr key={props.rowKey(r, i)}>
              {props.columns.map((c) => (
                <td key={c.key} className={c.align === 'right' ? 'num' : undefined}>
                  {c.render ? c.render(r) : String((r as Record<string, unknown>)[c.key] ?? '—')}
                </td>
              ))}
            </tr>
          ))}
        </tbody>
      </table>
    </div>
  );
}

export function Badge(props: {
  tone: Tone;
  children: ReactNode;
  plain?: boolean;
  title?: string;
  testId?: string;
}) {
  return (
    <span
      className={`ui-badge tone-${props.tone}${props.plain ? ' plain' : ''}`}
      title={props.title}
      data-testid={props.testId}
    >
      {props.children}
    </span>
  );
}

/** value 0..1, or null for indeterminate. */
export function ProgressBar(props: { value: number | null; label?: string }) {
  const pct = props.value === null ? null : Math.max(0, Math.min(1, props.value)) * 100;
  return (
    <div
      className={`ui-progress${pct === null ? ' indeterminate' : ''}`}
      role="progressbar"
      aria-label={props.label ?? 'progress'}
      aria-valuemin={0}
      aria-valuemax={100}
      aria-valuenow={pct === null ? undefined : Math.round(pct)}
    >
      <span style={{ width: `${pct ?? 30}%` }} />
    </div>
  );
}

export function Notice(props: {
  tone: Tone;
  title?: ReactNode;
  children?: ReactNode;
  testId?: string;
  role?: string;
}) {
  return (
    <div
      className={`ui-notice tone-${props.tone}`}
      role={props.role ?? (props.tone === 'bad' ? 'alert' : 'status')}
      data-testid={props.testId}
    >
      {props.title && <strong>{props.title}</strong>}
      {props.children && <p>{props.children}</p>}
    </div>
  );
}

export function EmptyState(props: { children: ReactNode }) {
  return <div className="ui-empty">{props.children}</div>;
}

export function Button(
  props: ButtonHTMLAttributes<HTMLButtonElement> & {
    variant?: 'primary' | 'secondary' | 'danger';
    small?: boolean;
    busy?: boolean;
  },
) {
  const { variant = 'secondary', small, busy, className, ...rest } = props;
  return (
    <button
      type="button"
      {...rest}
      aria-busy={busy || undefined}
      className={`ui-button ${variant}${small ? ' small' : ''}${busy ? ' busy' : ''} ${className ?? ''}`}
    />
  );
}

/** A labelled form row. `children` receives the id to put on the input. */
export function Field(props: {
  label: ReactNode;
  hint?: ReactNode;
  error?: ReactNode;
  children: (id: string) => ReactNode;
}) {
  const id = useId();
  return (
    <div className="ui-field">
      <label htmlFor={id}>{props.label}</label>
      {props.children(id)}
      {props.hint && <span className="hint">{props.hint}</span>}
      {props.error && (
        <span className="error" role="alert">
          {props.error}
        </span>
      )}
    </div>
  );
}

/** A modal dialog: focus moves in, Escape cancels. */
export function Dialog(props: {
  title: ReactNode;
  children: ReactNode;
  actions: ReactNode;
  onCancel: () => void;
  testId?: string;
}) {
  const ref = useRef<HTMLDivElement>(null);
  const { onCancel } = props;
  useEffect(() => {
    const el = ref.current;
    const first = el?.querySelector<HTMLElement>('[data-autofocus], button, input, select, textarea');
    first?.focus();
    const onKey = (e: KeyboardEvent) => {
      if (e.key === 'Escape') onCancel();
    };
    window.addEventListener('keydown', onKey);
    return () => window.removeEventListener('keydown', onKey);
  }, [onCancel]);
  return (
    <div className="ui-dialog-backdrop" onClick={(e) => e.target === e.currentTarget && onCancel()}>
      <div
        className="ui-dialog"
        role="dialog"
        aria-modal="true"
        aria-label={typeof props.title === 'string' ? props.title : undefined}
        ref={ref}
        data-testid={props.testId}
      >
        <h2>{props.title}</h2>
        <div>{props.children}</div>
        <div className="actions">{props.actions}</div>
      </div>
    </div>
  );
}
