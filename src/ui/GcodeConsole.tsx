import { useId, useLayoutEffect, useMemo, useRef, useState, type KeyboardEvent, type ReactNode } from 'react';
import { Button, Dialog, Notice, Panel, ScrollRegion } from './components';
import { formatTime } from './format';

/**
 * The one G-code console of every family that has one (Duet, g2core, Prunt, xTool): what was
 * sent and what came back, an input with history recall (↑/↓), Send, and the machine log where
 * the family wants it. Sending goes through the family's command runner (`useConsoleCommand` in
 * src/fleet/console.ts), so role checks, confirmation, in-flight state and the audit log are the
 * same as for every other command. The family passes only what differs: how a line is sent,
 * what its replies look like, which lines need a confirmation.
 */

/** One sent line (or block of lines) and what the controller made of it. */
export interface GcodeLine {
  key: string | number;
  /** ms since epoch */
  at: number;
  /** As sent; several lines keep their line breaks. */
  sent: string;
  /** The state in a word or two ("ok", "running", "Completed (ID 4)"). */
  status?: string;
  tone: 'pending' | 'ok' | 'bad' | 'neutral';
  /** Replies and output, one string a line. */
  reply?: readonly string[];
}

/** How this console sends: `useConsoleCommand` (src/fleet/console.ts) builds it from a command. */
export interface GcodeSender {
  /** The user's role allows sending at all; else the console is read-only and says why. */
  canSend: boolean;
  /** The least role that may send (for that sentence). */
  role: string;
  /** A line is on its way (through this console or elsewhere): no second send. */
  busy: boolean;
  /** Why nothing can be sent now (offline, machine busy…), or null; asked at render and at send. */
  blockedReason: () => string | null;
  /** The question to ask before sending this text, or null to send at once. */
  confirm: (text: string) => string | null;
  /** Sends; rejects with the reason (shown next to the input, the text stays). */
  send: (text: string) => Promise<unknown>;
}

export interface GcodeConsoleProps {
  sender: GcodeSender;
  /** Prefix of the test ids: root `<id>`, `<id>-input`, `<id>-send`, `<id>-error`, `<id>-history`, `<id>-entry-<key>`. */
  testId: string;
  title?: ReactNode;
  /** Panel header extras (a status badge). */
  actions?: ReactNode;
  /** Visible label of the input. */
  label?: string;
  placeholder?: string;
  /** Several lines at once: a text area, Ctrl+Enter (⌘+Enter) sends. */
  multiline?: boolean;
  /** What was sent and answered, oldest first. Absent: no own history (the machine log is it). */
  entries?: readonly GcodeLine[];
  /** Shown while `entries` is empty. */
  emptyText?: ReactNode;
  /** Earlier texts for ↑/↓ and the "Again" buttons, oldest first. Default: the sent texts of `entries`. */
  recall?: readonly string[];
  /** Controls next to Send (a family's send option). */
  options?: ReactNode;
  /** A remark above the history (what this controller does or does not report). */
  notice?: ReactNode;
  /** Below the input (an explanation of what is blocked). */
  footer?: ReactNode;
  /** The machine log, below the history. */
  log?: ReactNode;
}

const RECENT = 6;

/** Unique texts, oldest first, each at its last place. */
function uniqueRecall(texts: readonly string[]): string[] {
  const seen = new Set<string>();
  const out: string[] = [];
  for (let i = texts.length - 1; i >= 0; i--) {
    const t = texts[i];
    if (t === undefined || t.trim() === '' || seen.has(t)) continue;
    seen.add(t);
    out.push(t);
  }
  return out.reverse();
}

export function GcodeConsole(props: GcodeConsoleProps) {
  const { sender, testId, entries, multiline } = props;
  const inputId = useId();
  const hintId = useId();
  const [text, setText] = useState('');
  /** Index into `recall` while browsing it, null while editing. */
  const [pos, setPos] = useState<number | null>(null);
  const draft = useRef('');
  const [error, setError] = useState<string | null>(null);
  const [sending, setSending] = useState(false);
  const [asking, setAsking] = useState<{ text: string; question: string } | null>(null);
  const inputRef = useRef<HTMLInputElement & HTMLTextAreaElement>(null);
  const historyRef = useRef<HTMLDivElement>(null);

  const recall = useMemo(
    () => uniqueRecall(props.recall ?? (entries ?? []).map((e) => e.sent)),
    [props.recall, entries],
  );
  const busy = sender.busy || sending;
  const blocked = sender.blockedReason();

  // Newest at the bottom, in view.
  useLayoutEffect(() => {
    const el = historyRef.current;
    if (el) el.scrollTop = el.scrollHeight;
  }, [entries?.length]);

  const send = async (t: string) => {
    setAsking(null);
    setError(null);
    setSending(true);
    try {
      await sender.send(t);
      // Clear what was sent, not what was typed meanwhile.
      setText((cur) => (cur.trim() === t ? '' : cur));
      setPos(null);
    } catch (e) {
      setError(e instanceof Error ? e.message : String(e));
    } finally {
      setSending(false);
    }
  };

  const submit = () => {
    const t = text.trim();
    if (!t || busy) return;
    const reason = sender.blockedReason();
    if (reason) {
      // Tablets have no hover: the reason is said on screen, and nothing is sent.
      setError(`Not available: ${reason}`);
      return;
    }
    const question = sender.confirm(t);
    if (question) setAsking({ text: t, question });
    else void send(t);
  };

  const show = (p: number | null) => {
    setPos(p);
    setText(p === null ? draft.current : (recall[p] ?? ''));
  };

  const onKeyDown = (e: KeyboardEvent<HTMLInputElement | HTMLTextAreaElement>) => {
    const el = e.currentTarget;
    if (e.key === 'Enter' && (!multiline || e.ctrlKey || e.metaKey)) {
      e.preventDefault();
      submit();
      return;
    }
    // In a text area the arrows move the caret; they recall only from the first / last line.
    const before = el.value.slice(0, el.selectionStart ?? 0);
    const after = el.value.slice(el.selectionEnd ?? el.value.length);
    if (e.key === 'ArrowUp' && recall.length > 0 && !(multiline && before.includes('\n'))) {
      e.preventDefault();
      if (pos === null) draft.current = text;
      show(pos === null ? recall.length - 1 : Math.max(0, Math.min(pos, recall.length) - 1));
    } else if (e.key === 'ArrowDown' && pos !== null && !(multiline && after.includes('\n'))) {
      e.preventDefault();
      show(pos + 1 >= recall.length ? null : pos + 1);
    } else if (e.key === 'Escape' && pos !== null) {
      e.preventDefault();
      show(null);
    }
  };

  const inputProps = {
    id: inputId,
    ref: inputRef,
    className: 'ui-input mono ui-gcode-input',
    value: text,
    placeholder: props.placeholder,
    onChange: (e: { target: { value: string } }) => {
      setText(e.target.value);
      setPos(null);
    },
    onKeyDown,
    'aria-describedby': hintId,
    'data-testid': `${testId}-input`,
    autoCapitalize: 'characters',
    autoComplete: 'off',
    autoCorrect: 'off',
    spellCheck: false,
    enterKeyHint: multiline ? undefined : ('send' as const),
  };

  const recent = recall.slice(-RECENT).reverse();

  return (
    <Panel
      title={props.title ?? 'G-code console'}
      actions={props.actions}
      testId={testId}
      className="ui-gcode"
    >
      {!sender.canSend && (
        <Notice tone="info">Sending G-code needs the {sender.role} role. You can read the console.</Notice>
      )}
      {sender.canSend && (
        <form
          className="ui-gcode-form"
          onSubmit={(e) => {
            e.preventDefault();
            submit();
          }}
        >
          <label htmlFor={inputId}>{props.label ?? 'G-code'}</label>
          <div className="ui-row ui-gcode-send">
            {multiline ? <textarea rows={3} {...inputProps} /> : <input type="text" {...inputProps} />}
            {props.options}
            <Button
              type="submit"
              variant="primary"
              busy={busy}
              disabled={busy || text.trim() === ''}
              aria-disabled={blocked ? true : undefined}
              title={blocked ?? (text.trim() === '' ? 'Type a line first' : undefined)}
              data-testid={`${testId}-send`}
            >
              {busy ? 'Sending…' : 'Send'}
            </Button>
          </div>
          <span id={hintId} className="ui-muted ui-gcode-hint">
            {multiline
              ? 'Ctrl+Enter sends; ↑ on the first line recalls earlier ones.'
              : 'Enter sends; ↑/↓ recall earlier lines.'}
          </span>
          {error && (
            <p role="alert" className="ui-gcode-error" data-testid={`${testId}-error`}>
              {error}
            </p>
          )}
          {recent.length > 0 && (
            <div className="ui-row ui-gcode-recent" role="group" aria-label="Send again">
              <span className="ui-muted">Again:</span>
              {recent.map((r) => (
                <Button
                  key={r}
                  small
                  className="mono"
                  title={r}
                  onClick={() => {
                    setText(r);
                    setPos(null);
                    inputRef.current?.focus();
                  }}
                >
                  {r.split('\n')[0]}
                  {r.includes('\n') ? ' …' : ''}
                </Button>
              ))}
            </div>
          )}
          {props.footer}
        </form>
      )}
      {props.notice}
      {entries && (
        // The box scrolls; while it does it is a focusable region, so the keyboard can scroll it.
        <ScrollRegion
          className="ui-log ui-gcode-history"
          label="Sent G-code and replies"
          scrollRef={historyRef}
        >
          <div
            role="log"
            aria-live="polite"
            aria-label="Sent G-code and replies"
            data-testid={`${testId}-history`}
          >
            {entries.length === 0 && (
              <div className="ui-muted">{props.emptyText ?? 'Nothing sent from this page yet.'}</div>
            )}
            {entries.map((e) => (
              <div
                key={e.key}
                className={`ui-gcode-entry is-${e.tone}`}
                data-testid={`${testId}-entry-${e.key}`}
              >
                <span className="t">{formatTime(e.at)}</span>
                <span className="ui-gcode-sent">&gt; {e.sent}</span>
                {e.status && <span className="ui-gcode-status"> — {e.status}</span>}
                {e.reply?.map((r, i) => (
                  <div key={i} className="ui-gcode-reply">
                    {r}
                  </div>
                ))}
              </div>
            ))}
          </div>
        </ScrollRegion>
      )}
      {props.log}
      {asking && (
        <Dialog
          title="Send G-code?"
          onCancel={() => setAsking(null)}
          testId="confirm-dialog"
          role="alertdialog"
          actions={
            <>
              <Button onClick={() => setAsking(null)} data-autofocus>
                Cancel
              </Button>
              <Button variant="danger" data-testid="confirm-yes" onClick={() => void send(asking.text)}>
                Yes, send it
              </Button>
            </>
          }
        >
          <p>{asking.question}</p>
          <pre className="mono ui-gcode-sent">{asking.text}</pre>
        </Dialog>
      )}
    </Panel>
  );
}
