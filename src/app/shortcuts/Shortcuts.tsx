import './shortcuts.css';
import { Fragment, useEffect, useRef, useState } from 'react';
import { CommandNotConfirmed, type AnyCommand } from '../../fleet/commands';
import { getRuntime, type MachineRuntime } from '../../fleet/fleet';
import { Button, Dialog, STOP_CONTROLS } from '../../ui';
import { matchRoute, navigate } from '../router';
import { createKeyReader, pageBusy, SHORTCUTS, type ShortcutAction } from './keys';
import { neighbourMachine } from './order';
import { choosePauseResume } from './pause';

interface Asking {
  rt: MachineRuntime;
  command: AnyCommand;
  question: string;
}

/** How long a shortcut's message stays on screen (ms). */
const MESSAGE_MS = 6000;

/**
 * Keyboard shortcuts of the console (desktop): `?` shows them. They never fire while typing,
 * with Ctrl/Alt/Meta, or while a dialog is open, and never move focus to a stop control.
 */
export function Shortcuts() {
  const [help, setHelp] = useState(false);
  const [asking, setAsking] = useState<Asking | null>(null);
  const [message, setMessage] = useState<{ text: string; bad: boolean } | null>(null);
  const read = useRef(createKeyReader());

  useEffect(() => {
    if (!message) return;
    const t = setTimeout(() => setMessage(null), MESSAGE_MS);
    return () => clearTimeout(t);
  }, [message]);

  useEffect(() => {
    const perform = (action: ShortcutAction): boolean => {
      const route = matchRoute(location.pathname);
      switch (action) {
        case 'help':
          setHelp(true);
          return true;
        case 'go-fleet':
          navigate('/');
          return true;
        case 'go-alarms':
          navigate('/alarms');
          return true;
        case 'next':
        case 'previous': {
          if (route.name !== 'machine') return false;
          const to = neighbourMachine(route.id, action === 'next' ? 1 : -1);
          if (to) navigate(`/m/${encodeURIComponent(to)}`);
          return true;
        }
        case 'pause-resume': {
          if (route.name !== 'machine') return false;
          const rt = getRuntime(route.id);
          const commands = rt?.session?.commands;
          if (!rt || !commands) {
            setMessage({ text: 'This machine is not connected yet.', bad: true });
            return true;
          }
          const choice = choosePauseResume(commands, rt.commands, rt.info.name);
          if (choice.kind === 'none') {
            setMessage({ text: choice.reason, bad: true });
            return true;
          }
          // The dialog gives focus back where it was when it closes: never to a stop control.
          const active = document.activeElement;
          if (active instanceof HTMLElement && active.matches(STOP_CONTROLS)) active.blur();
          setAsking({ rt, command: choice.command, question: choice.question });
          return true;
        }
      }
    };
    const onKey = (e: KeyboardEvent) => {
      if (pageBusy(document)) return;
      const action = read.current(e);
      if (action && perform(action)) e.preventDefault();
    };
    document.addEventListener('keydown', onKey);
    return () => document.removeEventListener('keydown', onKey);
  }, []);

  const send = async (a: Asking) => {
    setAsking(null);
    try {
      const result = await a.rt.commands.run(a.command, undefined as never);
      setMessage({ text: `${a.rt.info.name}: ${a.command.label} — ${result}`, bad: false });
    } catch (e) {
      const text = e instanceof Error ? e.message : String(e);
      setMessage({
        text: `${a.rt.info.name}: ${e instanceof CommandNotConfirmed ? text : `${a.command.label} not sent — ${text}`}`,
        bad: true,
      });
    }
  };

  return (
    <>
      {help && (
        <Dialog
          title="Keyboard shortcuts"
          onCancel={() => setHelp(false)}
          testId="shortcuts-help"
          actions={
            <Button onClick={() => setHelp(false)} data-autofocus>
              Close
            </Button>
          }
        >
          <dl className="shortcut-list">
            {SHORTCUTS.map((s) => (
              <Fragment key={s.action}>
                <dt>
                  {s.keys.map((seq, i) => (
                    <Fragment key={seq.join(' ')}>
                      {i > 0 && ' or '}
                      {seq.map((k, j) => (
                        <Fragment key={k}>
                          {j > 0 && ' then '}
                          <kbd>{k}</kbd>
                        </Fragment>
                      ))}
                    </Fragment>
                  ))}
                </dt>
                <dd>{s.what}</dd>
              </Fragment>
            ))}
          </dl>
          <p className="ui-muted small">
            Shortcuts do nothing while you type in a field or a dialog is open.
          </p>
        </Dialog>
      )}
      {asking && (
        <Dialog
          title={`${asking.command.label} — ${asking.rt.info.name}`}
          onCancel={() => setAsking(null)}
          testId="confirm-dialog"
          role="alertdialog"
          actions={
            <>
              <Button onClick={() => setAsking(null)} data-autofocus>
                Cancel
              </Button>
              <Button variant="primary" data-testid="confirm-yes" onClick={() => void send(asking)}>
                Yes, {asking.command.label.toLowerCase()}
              </Button>
            </>
          }
        >
          <p>{asking.question}</p>
        </Dialog>
      )}
      {message && (
        <div
          className={`shortcut-message ${message.bad ? 'tone-warn' : 'tone-ok'}`}
          role="status"
          data-testid="shortcut-message"
        >
          {message.text}
        </div>
      )}
    </>
  );
}
