import { useState, type FormEvent } from 'react';
import { useStore } from 'zustand';
import { authStore } from '../../fleet/auth';
import { Badge, Button, Field, Notice, Panel } from '../../ui';
import { AuthError, login, logout, sessionExtra } from './api';
import { PinUnlock } from './UserControls';
import { usePageTitle } from '../router';
import './auth.css';

/** Where to go after logging in: `?next=/m/laser-1`, same origin only. */
export function nextPath(search: string): string {
  const n = new URLSearchParams(search).get('next');
  return n && n.startsWith('/') && !n.startsWith('//') && !n.startsWith('/\\') && n !== '/login' ? n : '/';
}

function LoginForm() {
  const expired = useStore(sessionExtra, (s) => s.expired);
  const signedOut = useStore(sessionExtra, (s) => s.signedOut);
  const [name, setName] = useState('');
  const [password, setPassword] = useState('');
  const [busy, setBusy] = useState(false);
  const [error, setError] = useState<string | null>(null);

  const submit = async (e: FormEvent) => {
    e.preventDefault();
    if (busy) return;
    if (!name.trim() || !password) {
      setError('Enter your name and password.');
      return;
    }
    setBusy(true);
    setError(null);
    try {
      await login(name.trim(), password);
      // A fresh start: the fleet and the sessions are loaded for this user.
      location.assign(nextPath(location.search));
    } catch (err) {
      setPassword('');
      setError(err instanceof AuthError || err instanceof Error ? err.message : String(err));
      setBusy(false);
    }
  };

  return (
    <form className="auth-form" onSubmit={(e) => void submit(e)} noValidate data-testid="login-form">
      {expired ? (
        <Notice tone="info" title="You were signed out">
          Your session ended after a while without activity. Sign in again.
        </Notice>
      ) : (
        signedOut && (
          <Notice tone="info" title="Signed out — sign in again">
            This screen&apos;s session ended (signed out, or removed on the server). Sign in again.
          </Notice>
        )
      )}
      <Field label="Name">
        {(id) => (
          <input
            id={id}
            className="ui-input"
            name="username"
            autoComplete="username"
            autoCapitalize="off"
            autoCorrect="off"
            spellCheck={false}
            value={name}
            onChange={(e) => setName(e.target.value)}
            aria-invalid={error ? true : undefined}
          />
        )}
      </Field>
      <Field label="Password">
        {(id) => (
          <input
            id={id}
            className="ui-input"
            type="password"
            name="password"
            autoComplete="current-password"
            value={password}
            onChange={(e) => setPassword(e.target.value)}
            aria-invalid={error ? true : undefined}
          />
        )}
      </Field>
      {error && (
        <Notice tone="bad" testId="login-error">
          {error}
        </Notice>
      )}
      <Button type="submit" variant="primary" busy={busy} disabled={busy} className="auth-submit">
        {busy ? 'Signing in…' : 'Sign in'}
      </Button>
    </form>
  );
}

/**
 * `/login`. In open mode it says that no login is needed (and what that means); signed in, it
 * shows who you are, the supervisor PIN unlock on an operator's tablet, and the way out.
 */
export function LoginPage() {
  const mode = useStore(authStore, (s) => s.mode);
  const user = useStore(authStore, (s) => s.user);
  const elevation = useStore(sessionExtra, (s) => s.elevation);
  usePageTitle(mode === 'secured' && !user ? 'Sign in' : 'Session');

  if (mode === 'open') {
    return (
      <div className="auth-page">
        <Panel title="No login needed" level={1} testId="login-open">
          <Notice tone="warn" title="Open mode">
            There is no users file, so anyone on this network can control these machines. Add users with{' '}
            <code>npm run user -- add &lt;name&gt; --role operator</code> to require a login.
          </Notice>
          <p>
            <a href="/">Go to the fleet</a>
          </p>
        </Panel>
      </div>
    );
  }

  if (mode === 'secured' && user) {
    const operatorName = elevation?.operator ?? user.name;
    return (
      <div className="auth-page">
        <Panel title="Signed in" level={1} testId="login-signed-in">
          <p className="ui-row">
            <strong data-testid="login-user">{operatorName}</strong>
            <Badge tone="info" plain>
              {elevation ? 'operator' : user.role}
            </Badge>
            {user.machines && <span className="ui-muted">machines: {user.machines.join(', ')}</span>}
          </p>
          <PinUnlock />
          <div className="ui-row auth-actions">
            <Button variant="primary" onClick={() => location.assign('/')}>
              Go to the fleet
            </Button>
            <Button onClick={() => void logout().then(() => location.assign('/login'))}>Sign out</Button>
          </div>
        </Panel>
      </div>
    );
  }

  return (
    <div className="auth-page">
      <Panel title="Sign in to Shopdeck" level={1} testId="login-page">
        <p className="ui-muted">
          The machines on this console fire lasers and move steel: who you are decides what you may do here.
        </p>
        <LoginForm />
      </Panel>
    </div>
  );
}
