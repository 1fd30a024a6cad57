import { useState } from 'react';
import type { TabProps } from '../../../fleet/contract';
import { describeError } from '../../../fleet/errors';
import { useCan, useSnapshot, useStoreSelect } from '../../../fleet/react';
import { Button, Field, Notice } from '../../../ui';
import type { TouchcutSession } from '../session';
import { defaultUsers } from '../sim-users';

/**
 * TouchCut user login (`POST rest/v1/auth`), performed by the console's server: the JWT stays
 * there, shared by every viewer of the machine, and never reaches this browser; the password is
 * not stored anywhere. Logging the machine in is an operator's (access.ts): a viewer is told so.
 */
export function LoginForm({ session }: TabProps<TouchcutSession>) {
  const { reason, notice } = useStoreSelect(session.store, (s) => ({
    reason: s.auth.reason,
    notice: s.notice,
  }));
  const needsLogin = useSnapshot(session.ctx, (s) => s.link === 'needs-login');
  const mayLogIn = useCan('operator');
  const [username, setUsername] = useState('');
  const [password, setPassword] = useState('');
  const [busy, setBusy] = useState(false);
  const [error, setError] = useState<string | null>(null);
  const submit = async () => {
    setBusy(true);
    setError(null);
    try {
      await session.login({ username, password });
      setPassword('');
    } catch (e) {
      setError(describeError(e));
    } finally {
      setBusy(false);
    }
  };
  if (!mayLogIn) {
    return (
      <div className="tc-form" data-testid="touchcut-login">
        {reason && <p>{reason}</p>}
        {notice && <Notice tone="info">{notice}</Notice>}
        <p className="ui-muted" data-testid="touchcut-login-needs-operator">
          Logging this machine in to TouchCut is for an operator or a supervisor: the login is shared by
          everyone who views the machine.
        </p>
        {needsLogin && <Button onClick={() => session.retryWithoutLogin()}>Try again without a login</Button>}
      </div>
    );
  }
  return (
    <form
      className="tc-form"
      data-testid="touchcut-login"
      onSubmit={(e) => {
        e.preventDefault();
        if (!busy) void submit();
      }}
    >
      {reason && <p>{reason}</p>}
      {notice && <Notice tone="info">{notice}</Notice>}
      <div className="ui-row">
        <Field label="TouchCut user">
          {(id) => (
            <input
              id={id}
              className="ui-input"
              autoComplete="username"
              value={username}
              onChange={(e) => setUsername(e.target.value)}
              data-testid="touchcut-username"
            />
          )}
        </Field>
        <Field label="Password">
          {(id) => (
            <input
              id={id}
              className="ui-input"
              type="password"
              autoComplete="current-password"
              value={password}
              onChange={(e) => setPassword(e.target.value)}
              data-testid="touchcut-password"
            />
          )}
        </Field>
      </div>
      {error && (
        <p role="alert" style={{ color: 'var(--bad)' }} data-testid="touchcut-login-error">
          {error}
        </p>
      )}
      <div className="ui-row">
        <Button
          type="submit"
          variant="primary"
          busy={busy}
          disabled={busy}
          data-testid="touchcut-login-submit"
        >
          Log in
        </Button>
        {needsLogin && <Button onClick={() => session.retryWithoutLogin()}>Try again without a login</Button>}
      </div>
      {session.machine.simulated && (
        <p className="ui-muted small" data-testid="touchcut-sim-users">
          Simulated machine — simulated TouchCut users:{' '}
          {defaultUsers()
            .map((u) => `${u.username} / ${u.password} (${u.group})`)
            .join(', ')}
          .
        </p>
      )}
    </form>
  );
}
