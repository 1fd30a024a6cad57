import { useEffect, useMemo, useRef, useState, type ReactNode } from 'react';
import { ESTOP_QUESTION, ESTOP_SAID, useEstopConfirm } from '../../../fleet/estop-confirm';
import { CommandButton, useScheduler, useSnapshot, useStoreSelect } from '../../../fleet/react';
import { Button, Dialog, Field, Notice } from '../../../ui';
import { imageDataUrl } from '../../../ui/safe-url';
import type { DuetSession } from '../session';
import { validateBoxValue } from '../session';
import type { MessageBox, Thumbnail as ThumbnailData } from '../wire';
import { base64ToBytes, decodeQoi } from './qoi';

/** Thumbnail formats shown as data URLs; anything else (and QOI, drawn on a canvas) is not. */
const THUMBNAIL_TYPES: Readonly<Record<string, string>> = { png: 'image/png', jpeg: 'image/jpeg' };

/**
 * The data URL of a PNG or JPEG thumbnail, or null. Format and data come from the controller:
 * only an image type we name and base64 data can make the URL (`imageDataUrl`), so no
 * `data:text/html`, SVG or text that breaks out of the URL.
 */
export function thumbnailSrc(format: string, data: string): string | null {
  const type = Object.hasOwn(THUMBNAIL_TYPES, format) ? THUMBNAIL_TYPES[format] : undefined;
  return type ? imageDataUrl(type, data) : null;
}

/** A job-file thumbnail: PNG and JPEG as data URLs, QOI decoded onto a canvas. */
export function Thumbnail(props: { thumb: ThumbnailData | null | undefined; size?: number; alt?: string }) {
  const size = props.size ?? 48;
  const t = props.thumb;
  const canvas = useRef<HTMLCanvasElement>(null);
  const qoi = useMemo(() => {
    if (!t?.data || t.format !== 'qoi') return null;
    try {
      return decodeQoi(base64ToBytes(t.data));
    } catch {
      return null;
    }
  }, [t]);
  useEffect(() => {
    const c = canvas.current;
    if (!c || !qoi) return;
    c.width = qoi.width;
    c.height = qoi.height;
    const g = c.getContext('2d');
    if (!g) return;
    g.putImageData(new ImageData(new Uint8ClampedArray(qoi.data), qoi.width, qoi.height), 0, 0);
  }, [qoi]);
  const box = {
    width: size,
    height: size,
    borderRadius: 6,
    background: 'var(--panel-2)',
    flex: 'none' as const,
    objectFit: 'contain' as const,
  };
  if (!t?.data) return <span style={{ ...box, display: 'inline-block' }} aria-hidden="true" />;
  if (t.format === 'qoi') {
    return qoi ? (
      <canvas
        ref={canvas}
        style={box}
        role="img"
        aria-label={props.alt ?? 'thumbnail (QOI)'}
        data-format="qoi"
      />
    ) : (
      <span style={box} />
    );
  }
  const src = thumbnailSrc(t.format, t.data);
  if (!src) return <span style={{ ...box, display: 'inline-block' }} aria-hidden="true" data-format="none" />;
  return <img src={src} alt={props.alt ?? 'thumbnail'} style={box} data-format={t.format} />;
}

/**
 * The status line over every Duet page (halted, a hidden message box). The emergency stop is in the
 * machine page's job control row (src/app/kiosk/JobControls.tsx), on every page of the machine.
 */
export function EstopBar({ session }: { session: DuetSession }) {
  const { status, box, dismissed } = useStoreSelect(session.store, (s) => ({
    status: s.model?.state.status ?? null,
    box: s.model?.state.messageBox ?? null,
    dismissed: s.dismissedBoxes,
  }));
  const hidden = box && dismissed.includes(box.seq) ? box : null;
  return (
    <div className="ui-row" style={{ justifyContent: 'space-between', marginBottom: 12 }}>
      <span className="ui-row" data-testid="duet-status-line">
        {status === 'halted' && (
          <span className="ui-muted">Halted: emergency stop. The board is being reset.</span>
        )}
        {hidden && (
          <Button
            variant="primary"
            onClick={() => session.reopenBox(hidden.seq)}
            data-testid="duet-messagebox-reopen"
          >
            Message from the machine: {hidden.title || 'open'}
          </Button>
        )}
      </span>
    </div>
  );
}

const MODE_WORDS: Record<number, string> = {
  0: 'Message',
  1: 'Message',
  2: 'Confirm',
  3: 'Confirm or cancel',
  4: 'Choose',
  5: 'Enter a whole number',
  6: 'Enter a number',
  7: 'Enter text',
};

/**
 * `state.messageBox` as a dialog for every mode 0–7. Mode 0 has no buttons (it closes by
 * timeout or from the machine); we still let the user hide it locally. The answer is M292 as the
 * firmware expects (see messageBoxReply).
 */
export function MessageBoxDialog({ session, onEstop }: { session: DuetSession; onEstop?: () => void }) {
  const { box, dismissed } = useStoreSelect(session.store, (s) => ({
    box: s.model?.state.messageBox ?? null,
    dismissed: s.dismissedBoxes,
  }));
  if (!box || dismissed.includes(box.seq)) return null;
  // One dialog per box (`key`): it takes focus once when the box appears, not on each model frame.
  return (
    <MessageBoxBody
      key={box.seq}
      box={box}
      session={session}
      onHide={() => session.dismissBox(box.seq)}
      onEstop={onEstop}
    />
  );
}

function MessageBoxBody(props: {
  box: MessageBox;
  session: DuetSession;
  onHide: () => void;
  onEstop?: () => void;
}) {
  const { box, session } = props;
  // The same question as the job control row's emergency stop: this console's setting (on by
  // default on touch screens), asked over the message box.
  const estopConfirm = useEstopConfirm();
  const ctx = session.ctx;
  const link = useSnapshot(ctx, (s) => s.link);
  const [text, setText] = useState(() =>
    box.default === null || box.default === undefined ? '' : String(box.default),
  );
  const [choice, setChoice] = useState<number>(() => (typeof box.default === 'number' ? box.default : 0));
  const input = box.mode >= 5 && box.mode <= 7;
  const checked = input ? validateBoxValue(box, text) : null;
  const error = checked && 'error' in checked ? checked.error : null;
  const value = box.mode === 4 ? choice : checked && 'value' in checked ? checked.value : undefined;
  const cmd = session.cmd.answer;
  const [remaining, setRemaining] = useState<number | null>(box.timeout > 0 ? box.timeout : null);
  const scheduler = useScheduler();
  useEffect(() => {
    if (box.timeout <= 0) return;
    const started = scheduler.now();
    return scheduler.every(500, () =>
      setRemaining(Math.max(0, Math.ceil(box.timeout - (scheduler.now() - started) / 1000))),
    );
  }, [box.timeout, scheduler]);
  const okLabel = box.mode === 1 ? 'Close' : 'OK';
  const showCancel = box.mode === 3 || (box.cancelButton && box.mode >= 2);
  const axisList = useStoreSelect(session.store, (s) => s.model?.move.axes ?? null);
  const axes = (axisList ?? []).map((a) => a?.letter ?? '');
  const jogAxes = axes.filter((_, i) => (box.axisControls & (1 << i)) !== 0);

  return (
    <Dialog
      title={box.title || MODE_WORDS[box.mode] || 'Message'}
      onCancel={props.onHide}
      testId="duet-messagebox"
      actions={
        <>
          {/* The dialog covers the page: the emergency stop must stay reachable (never focused by itself). */}
          <CommandButton
            runner={ctx.commands}
            snapshot={ctx.snapshot}
            command={session.cmd.estop}
            args={undefined}
            variant="danger"
            testId="duet-messagebox-estop"
            confirmText={estopConfirm ? ESTOP_QUESTION : undefined}
            dismissLabel="Keep running"
            onDone={() => props.onEstop?.()}
          >
            Emergency stop
          </CommandButton>
          {/* Focus starts here, or on the input: nothing is sent by an Enter the user did not mean. */}
          <Button
            onClick={props.onHide}
            data-testid="duet-messagebox-hide"
            data-autofocus={input ? undefined : true}
          >
            {box.mode <= 1 ? 'Hide' : 'Later'}
          </Button>
          {showCancel && (
            <CommandButton
              runner={ctx.commands}
              snapshot={ctx.snapshot}
              command={cmd}
              args={{ box, cancel: true }}
              testId="duet-messagebox-cancel"
            >
              Cancel
            </CommandButton>
          )}
          {box.mode >= 1 && (
            <CommandButton
              runner={ctx.commands}
              snapshot={ctx.snapshot}
              command={cmd}
              args={error ? { box, value: undefined } : { box, value }}
              variant="primary"
              testId="duet-messagebox-ok"
            >
              {okLabel}
            </CommandButton>
          )}
        </>
      }
    >
      <p style={{ whiteSpace: 'pre-wrap' }} data-testid="duet-messagebox-text">
        {box.message}
      </p>
      {link !== 'online' && (
        <Notice tone="warn">The machine is not connected: the answer cannot be sent now.</Notice>
      )}
      {box.mode === 4 && (
        <div className="ui-row" role="group" aria-label="Choices">
          {(box.choices ?? []).map((c, i) => (
            <Button
              key={i}
              variant={i === choice ? 'primary' : 'secondary'}
              aria-pressed={i === choice}
              onClick={() => setChoice(i)}
              data-testid={`duet-choice-${i}`}
            >
              {c}
            </Button>
          ))}
        </div>
      )}
      {input && (
        <Field
          label={`${MODE_WORDS[box.mode]}${box.min !== null || box.max !== null ? ` (${box.min ?? '…'} – ${box.max ?? '…'}${box.mode === 7 ? ' characters' : ''})` : ''}`}
          error={error}
        >
          {(id) => (
            <input
              id={id}
              className="ui-input"
              inputMode={box.mode === 7 ? 'text' : box.mode === 5 ? 'numeric' : 'decimal'}
              value={text}
              aria-invalid={error ? true : undefined}
              onChange={(e) => setText(e.target.value)}
              data-testid="duet-messagebox-input"
              data-autofocus
              style={{ minHeight: 44, fontSize: 18 }}
            />
          )}
        </Field>
      )}
      {jogAxes.length > 0 && <JogControls session={session} axes={jogAxes} />}
      {remaining !== null && <p className="ui-muted">Closes by itself in {remaining} s.</p>}
    </Dialog>
  );
}

/** Jog buttons for the axes a message box asks for (M291 … Z1): relative moves, supervisor-free. */
function JogControls({ session, axes }: { session: DuetSession; axes: string[] }) {
  const ctx = session.ctx;
  const steps = [-1, -0.1, 0.1, 1];
  return (
    <div data-testid="duet-jog" style={{ display: 'grid', gap: 6, marginTop: 8 }}>
      {axes.map((a) => (
        <div className="ui-row" key={a}>
          <strong style={{ width: 24 }}>{a}</strong>
          {steps.map((s) => (
            <CommandButton
              key={s}
              runner={ctx.commands}
              snapshot={ctx.snapshot}
              command={session.cmd.console}
              args={{ code: `M120\nG91\nG1 ${a}${s} F600\nM121` }}
            >
              {s > 0 ? `+${s}` : String(s)}
            </CommandButton>
          ))}
        </div>
      ))}
      <span className="ui-muted">Jogging sends G-code: it needs the supervisor role.</span>
    </div>
  );
}

/**
 * Every Duet page: emergency stop on top, the message box when the machine asks, then the
 * content. (The machine page itself shows link problems and the login form.)
 */
export function DuetFrame({ session, children }: { session: DuetSession; children: ReactNode }) {
  // An emergency stop from the message box: said on the page (the box itself goes with the reset).
  const [estopSaid, setEstopSaid] = useState(false);
  return (
    <div data-testid="duet-page">
      <EstopBar session={session} />
      {estopSaid && (
        <p className="job-said" role="status" data-testid="duet-estop-said">
          {ESTOP_SAID}
        </p>
      )}
      <PollingNotice session={session} />
      <MessageBoxDialog session={session} onEstop={() => setEstopSaid(true)} />
      {children}
    </div>
  );
}

/** While the socket is down but `GET /machine/model` answers, the data is polled: say so. */
function PollingNotice({ session }: { session: DuetSession }) {
  const { transport, problem } = useStoreSelect(session.store, (s) => ({
    transport: s.transport,
    problem: s.socketProblem,
  }));
  const link = useSnapshot(session.ctx, (s) => s.link);
  if (transport !== 'polling' || link !== 'online') return null;
  return (
    <Notice tone="warn" testId="duet-polling">
      Live updates unavailable{problem ? ` (${problem})` : ''}: the status is polled every 2 s and may lag.
      The live connection is retried.
    </Notice>
  );
}
