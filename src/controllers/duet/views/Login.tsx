import { useState } from 'react';
import type { TabProps } from '../../../fleet/contract';
import { Button, Field, Notice } from '../../../ui';
import type { DuetSession } from '../session';

/**
 * Needs login: DSF answered `GET /machine/connect` with 403 and the gateway has no password for
 * this machine. The password goes to the machine with the connect request only.
 */
export function LoginForm({ session }: TabProps<DuetSession>) {
  const [password, setPassword] = useState('');
  const [error, setError] = useState<string | null>(null);
  const [busy, setBusy] = useState(false);
  const submit = async () => {
    setBusy(true);
    setError(null);
    try {
      await session.login({ password });
      setPassword('');
    } catch (e) {
      setError(e instanceof Error ? e.message : String(e));
    } finally {
      setBusy(false);
    }
  };
  return (
    <form
      onSubmit={(e) => {
        e.preventDefault();
        void submit();
      }}
      data-testid="duet-login"
    >
      <Notice tone="warn" title="This Duet needs its password">
        The machine refused the connection. Enter the DSF password (set with M551), or ask the administrator
        to put it in the machines file so the console logs in by itself.
      </Notice>
      <Field label="Password" error={error}>
        {(id) => (
          <input
            id={id}
            type="password"
            className="ui-input"
            value={password}
            onChange={(e) => setPassword(e.target.value)}
            autoComplete="current-password"
            style={{ minHeight: 44 }}
          />
        )}
      </Field>
      <Button type="submit" variant="primary" busy={busy} disabled={busy}>
        Connect
      </Button>
    </form>
  );
}
