import {
  useCallback,
  useId,
  useLayoutEffect,
  useRef,
  useState,
  type ButtonHTMLAttributes,
  type CSSProperties,
  type ReactNode,
  type RefObject,
} from 'react';

export type Tone = 'ok' | 'warn' | 'bad' | 'info' | 'muted' | 'paused';

export function Panel(props: {
  title?: ReactNode;
  actions?: ReactNode;
  children: ReactNode;
  className?: string;
  testId?: string;
  /** 1 when the panel's title is its page's heading (one h1 a page); 2 otherwise. */
  level?: 1 | 2;
}) {
  const H = props.level === 1 ? 'h1' : 'h2';
  return (
    <section className={`ui-panel ${props.className ?? ''}`} data-testid={props.testId}>
      {(props.title || props.actions) && (
        <header>
          {props.title ? <H>{props.title}</H> : <span />}
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

/**
 * Whether the element's content overflows it (it scrolls), followed as either resizes. A box
 * that scrolls and holds nothing focusable must be focusable itself (`tabIndex={0}` while this is
 * true), or the keyboard cannot scroll it (WCAG 2.1.1).
 */
export function useOverflows(ref: RefObject<HTMLElement | null>): boolean {
  const [overflows, setOverflows] = useState(false);
  useLayoutEffect(() => {
    const el = ref.current;
    if (!el) return;
    const check = () => setOverflows(el.scrollWidth > el.clientWidth || el.scrollHeight > el.clientHeight);
    check();
    if (typeof ResizeObserver === 'undefined') return;
    const watch = new ResizeObserver(check);
    watch.observe(el);
    for (const child of Array.from(el.children)) watch.observe(child);
    // Children come and go (log lines): watch the new ones too.
    const added = new MutationObserver((records) => {
      for (const r of records)
        for (const n of Array.from(r.addedNodes)) if (n instanceof Element) watch.observe(n);
      check();
    });
    added.observe(el, { childList: true });
    return () => {
      watch.disconnect();
      added.disconnect();
    };
  }, [ref]);
  return overflows;
}

/**
 * A box that scrolls what it holds (a wide table). While its content overflows it is a named,
 * focusable region, so the keyboard can scroll it too (WCAG 2.1.1).
 */
export function ScrollRegion(props: {
  label: string;
  className?: string;
  style?: CSSProperties;
  children: ReactNode;
  /** The scrolling element, for the owner (scroll to the newest line). */
  scrollRef?: RefObject<HTMLDivElement | null>;
}) {
  const own = useRef<HTMLDivElement>(null);
  const ref = props.scrollRef ?? own;
  const scrolls = useOverflows(ref);
  return (
    <div
      ref={ref}
      className={props.className}
      style={props.style}
      role={scrolls ? 'region' : undefined}
      aria-label={scrolls ? props.label : undefined}
      tabIndex={scrolls ? 0 : undefined}
    >
      {props.children}
    </div>
  );
}

export function DataTable<T>(props: {
  columns: Column<T>[];
  rows: readonly T[];
  rowKey: (row: T, index: number) => string;
  empty?: ReactNode;
  caption?: ReactNode;
  /** The name of the table's scroll region (when it scrolls); default the caption. */
  label?: string;
  testId?: string;
}) {
  if (props.rows.length === 0) return <EmptyState>{props.empty ?? 'Nothing to show.'}</EmptyState>;
  const label = props.label ?? (typeof props.caption === 'string' ? props.caption : 'Table');
  return (
    <ScrollRegion className="ui-table-wrap" label={label}>
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
    </ScrollRegion>
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
      <span style={pct === null ? undefined : { transform: `scaleX(${pct / 100})` }} />
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

/** While a view's code loads (a chunk of its own): says so, politely, without moving focus. */
export function Loading() {
  return (
    <div className="ui-empty" role="status" aria-live="polite" data-testid="view-loading">
      Loading…
    </div>
  );
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

/**
 * Controls that stop a machine (emergency stop, kill, stop job). Nothing may put focus on one by
 * itself: a stray Enter would send it. Mark them with `data-stop`.
 */
export const STOP_CONTROLS = '[data-stop]';

const FOCUSABLE =
  'button, [href], input:not([type="hidden"]), select, textarea, [tabindex]:not([tabindex="-1"])';

/** Where focus goes when a dialog opens: `[data-autofocus]`, else the first control; never a stop control. */
function initialFocus(dialog: HTMLElement): HTMLElement {
  const usable = (el: HTMLElement) =>
    !el.matches(STOP_CONTROLS) &&
    !el.closest('[hidden], [inert], [aria-hidden="true"]') &&
    !(el as HTMLButtonElement).disabled;
  const marked = [...dialog.querySelectorAll<HTMLElement>('[data-autofocus]')].find(usable);
  return marked ?? [...dialog.querySelectorAll<HTMLElement>(FOCUSABLE)].find(usable) ?? dialog;
}

/** The opener of a dialog closing in this task (for a dialog that replaces it). */
let returningTo: HTMLElement | null = null;

/**
 * A modal dialog on the native `<dialog>` with `showModal()`: the page behind is inert and focus
 * stays inside. Focus moves in ONCE when it opens (to `[data-autofocus]`, else the first control,
 * never a stop control; again only when `focusKey` changes) and back to the opener when it
 * closes. Escape (the `cancel` event) and a tap on the backdrop call `onCancel`, unless
 * `dismissible` is false. Re-renders (a status update, a model frame) never move focus.
 *
 * `role="alertdialog"` for confirmations and alarms that interrupt; `dialog` otherwise. Where
 * `showModal` is missing (test DOMs) it falls back to the `open` attribute.
 */
export function Dialog(props: {
  title: ReactNode;
  children: ReactNode;
  actions?: ReactNode;
  onCancel?: () => void;
  testId?: string;
  role?: 'dialog' | 'alertdialog';
  /** Change it to move focus to the initial control again (a second question in the same dialog). */
  focusKey?: string | number;
  /** Where focus goes on open: a control (default) or the dialog itself (an alarm: read it first). */
  initialFocus?: 'control' | 'dialog';
  /** False: Escape and the backdrop do nothing (a blocking alarm must be acknowledged). */
  dismissible?: boolean;
  className?: string;
}) {
  const ref = useRef<HTMLDialogElement>(null);
  const titleId = useId();
  const bodyId = useId();
  // Kept in refs: a new `onCancel` each render must not re-run the effects below.
  const onCancel = useRef(props.onCancel);
  const dismissible = useRef(props.dismissible !== false);
  const focusDialog = useRef(props.initialFocus === 'dialog');
  useLayoutEffect(() => {
    onCancel.current = props.onCancel;
    dismissible.current = props.dismissible !== false;
    focusDialog.current = props.initialFocus === 'dialog';
  });

  const moveFocusIn = useCallback(() => {
    const el = ref.current;
    if (!el) return;
    (focusDialog.current ? el : initialFocus(el)).focus({ preventScroll: true });
  }, []);

  // Open once: modal, listeners, and on close the focus back where it was.
  useLayoutEffect(() => {
    const el = ref.current;
    if (!el) return;
    const active = document.activeElement;
    // The control that opened it; a dialog that replaces one closing in the same commit (the
    // next message box) inherits that one's opener.
    const opener = active instanceof HTMLElement && active !== document.body ? active : returningTo;
    let alive = true;
    /** Closes we make ourselves (their `close` events come later, in a task of their own). */
    let ownCloses = 0;
    let answered = false;
    let pressedOnBackdrop = false;

    const showModal = () => {
      if (typeof el.showModal === 'function') {
        try {
          if (el.open) {
            ownCloses++;
            el.close();
          }
          el.showModal();
          return;
        } catch {
          // Not connected or not supported: the attribute below.
        }
      }
      el.setAttribute('open', '');
    };

    // Under an inert page (a blocking alarm is up) a modal would lock out the alarm: open in
    // place, and become modal when the page is live again.
    const inertHost = el.parentElement?.closest<HTMLElement>('[inert]') ?? null;
    let watch: MutationObserver | null = null;
    if (inertHost) {
      el.setAttribute('open', '');
      watch = new MutationObserver(() => {
        if (inertHost.hasAttribute('inert')) return;
        watch?.disconnect();
        watch = null;
        showModal();
        moveFocusIn();
      });
      watch.observe(inertHost, { attributes: true, attributeFilter: ['inert'] });
    } else {
      showModal();
    }

    /** One answer per close request (Escape can bring a keydown, a `cancel` and a `close`). */
    const cancel = () => {
      if (answered || !dismissible.current) return;
      answered = true;
      setTimeout(() => (answered = false), 0);
      onCancel.current?.();
    };
    const onCancelEvent = (e: Event) => {
      e.preventDefault();
      cancel();
    };
    const onClose = () => {
      if (ownCloses > 0) {
        ownCloses--;
        return;
      }
      if (!alive) return;
      // The browser closed it anyway (repeated Escape): the owner decides, or it opens again.
      if (dismissible.current) cancel();
      else showModal();
    };
    const onKeyDown = (e: KeyboardEvent) => {
      if (e.key !== 'Escape' || e.defaultPrevented) return;
      // Only for this dialog, not for one opened inside it.
      if (e.target instanceof Element && e.target.closest('dialog') !== el) return;
      // Browsers turn Escape into a `cancel` event; where none comes (a test DOM), cancel here.
      setTimeout(() => alive && cancel(), 0);
    };
    // The backdrop: a press and its click on the <dialog> itself, outside its content box (not a
    // text selection that started inside and ended outside).
    const onPointerDown = (e: PointerEvent) => {
      pressedOnBackdrop = e.target === el;
    };
    const onClick = (e: MouseEvent) => {
      if (e.target === el && pressedOnBackdrop) cancel();
      pressedOnBackdrop = false;
    };
    el.addEventListener('cancel', onCancelEvent);
    el.addEventListener('close', onClose);
    el.addEventListener('keydown', onKeyDown);
    el.addEventListener('pointerdown', onPointerDown);
    el.addEventListener('click', onClick);
    return () => {
      alive = false;
      watch?.disconnect();
      el.removeEventListener('cancel', onCancelEvent);
      el.removeEventListener('close', onClose);
      el.removeEventListener('keydown', onKeyDown);
      el.removeEventListener('pointerdown', onPointerDown);
      el.removeEventListener('click', onClick);
      const focusWasInside = el.contains(document.activeElement) || document.activeElement === document.body;
      if (el.open && typeof el.close === 'function') el.close();
      else el.removeAttribute('open');
      if (!focusWasInside || !opener) return;
      // Never back onto a stop control (the browser's own close puts it there): a stray Enter would
      // send it again. Focus leaves it instead.
      if (opener.matches(STOP_CONTROLS)) {
        queueMicrotask(() => {
          const now = document.activeElement;
          if (now instanceof HTMLElement && now.closest(STOP_CONTROLS)) now.blur();
        });
        return;
      }
      // Focus back to the opener once the commit is done (the page may stop being inert in it),
      // unless another dialog took focus meanwhile.
      returningTo = opener;
      queueMicrotask(() => {
        if (returningTo === opener) returningTo = null;
        const now = document.activeElement;
        if (now && now !== document.body && !el.contains(now)) return;
        if (opener.isConnected && !opener.closest('[inert]')) opener.focus({ preventScroll: true });
      });
    };
  }, [moveFocusIn]);

  // Focus in once on open, and again only when the question changes (`focusKey`).
  useLayoutEffect(() => {
    moveFocusIn();
  }, [moveFocusIn, props.focusKey]);

  return (
    <dialog
      ref={ref}
      className={`ui-dialog ${props.className ?? ''}`}
      role={props.role === 'alertdialog' ? 'alertdialog' : undefined}
      aria-labelledby={titleId}
      aria-describedby={props.role === 'alertdialog' ? bodyId : undefined}
      tabIndex={-1}
      data-testid={props.testId}
    >
      <div className="ui-dialog-content">
        <h2 id={titleId}>{props.title}</h2>
        <div id={bodyId}>{props.children}</div>
        {props.actions && <div className="actions">{props.actions}</div>}
      </div>
    </dialog>
  );
}
